// Files written whole or not at all: the target changes only on commit(), and nothing is left behind otherwise.
#include "fileio/whole_file.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "tests/support/run_command.hpp"
#include "tests/support/temp_dir.hpp"

namespace imubridge::test {
namespace {

namespace fs = std::filesystem;

std::size_t entries(const fs::path& dir) {
  return static_cast<std::size_t>(std::distance(fs::directory_iterator(dir), fs::directory_iterator()));
}

TEST(WholeFile, ReplacesTheTargetOnlyOnCommit) {
  TempDir dir;
  const fs::path target = dir / "out.csv";
  std::ofstream(target) << "old content\n";
  {
    fileio::WholeFile file(target);
    file.stream() << "new";
    EXPECT_EQ(slurp(target), "old content\n") << "before commit";
    EXPECT_EQ(entries(dir.path()), 2u);  // the target and the hidden temporary file
    file.stream() << " content\n";
    file.commit();
  }
  EXPECT_EQ(slurp(target), "new content\n");
  EXPECT_EQ(entries(dir.path()), 1u);
}

TEST(WholeFile, WithoutCommitTheTargetStaysAndNoTemporaryFileRemains) {
  TempDir dir;
  const fs::path target = dir / "params.json";
  std::ofstream(target) << "{}\n";
  try {
    fileio::WholeFile file(target);
    file.stream() << "half of a fi";
    throw std::runtime_error("the command failed half-way");
  } catch (const std::runtime_error&) {
  }
  EXPECT_EQ(slurp(target), "{}\n");
  EXPECT_EQ(entries(dir.path()), 1u);
  { fileio::WholeFile never_written(dir / "new.json"); }
  EXPECT_FALSE(fs::exists(dir / "new.json"));
  EXPECT_EQ(entries(dir.path()), 1u);
}

TEST(WholeFile, KeepsAnExistingFilesModeAndGivesANewOneTheUsualMode) {
  TempDir dir;
  const fs::path existing = dir / "shared.csv";
  std::ofstream(existing) << "x\n";
  fs::permissions(existing, fs::perms(0640));
  fileio::write_whole_file(existing, "y\n");
  EXPECT_EQ(fs::status(existing).permissions() & fs::perms::all, fs::perms(0640));
  const mode_t mask = ::umask(022);
  fileio::write_whole_file(dir / "fresh.csv", "z\n");
  ::umask(mask);
  EXPECT_EQ(fs::status(dir / "fresh.csv").permissions() & fs::perms::all, fs::perms(0644))
      << "not mkstemp's 0600: others read an export as they would any file";
}

TEST(WholeFile, UnwritablePlacesAreOneLineErrors) {
  TempDir dir;
  try {
    fileio::write_whole_file(dir / "no such folder" / "out.csv", "x");
    FAIL() << "wrote into a missing folder";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot write"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("no such folder/out.csv"), std::string::npos) << e.what();
  }
  EXPECT_THROW(fileio::write_whole_file(dir.path(), "x"), std::runtime_error);  // a directory
}

}  // namespace
}  // namespace imubridge::test
