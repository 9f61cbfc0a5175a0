// The daemon's [sync] finds every file of its station: the configured store and the files rotations continued in
// beside it, each under its own name in the archive (their session ids start at 1 again).
#include <gtest/gtest.h>

#include <fstream>

#include "daemon/archive_sync.hpp"
#include "tests/support/temp_dir.hpp"

namespace imubridge::daemon {
namespace {

TEST(ArchiveSync, TheStationsFilesAreTheStoreAndItsRotationsInNameOrder) {
  test::TempDir dir;
  for (const char* name :
       {"imubridge-20240522-090000.db", "imubridge.db", "imubridge.db-wal", "imubridge-20240521-143000.db",
        "imubridge-20240521-143000.db-wal", "imubridge-20240521-143000-2.db", "other.db", "imubridge.toml"}) {
    std::ofstream(dir / name) << "x";
  }
  const auto store = dir / "imubridge.db";
  const auto files = station_store_files(store);
  ASSERT_EQ(files.size(), 4u);
  EXPECT_EQ(files[0], store);
  EXPECT_EQ(files[1].filename(), "imubridge-20240521-143000-2.db");
  EXPECT_EQ(files[2].filename(), "imubridge-20240521-143000.db");
  EXPECT_EQ(files[3].filename(), "imubridge-20240522-090000.db");
  EXPECT_EQ(archive_station("gs1", store, files[0]), "gs1");
  EXPECT_EQ(archive_station("gs1", store, files[2]), "gs1/imubridge-20240521-143000");
}

TEST(ArchiveSync, ARotatedFileAloneIsStillFound) {
  test::TempDir dir;
  std::ofstream(dir / "imubridge-20240521-143000.db") << "x";
  const auto files = station_store_files(dir / "imubridge.db");  // the configured file was moved away
  ASSERT_EQ(files.size(), 1u);
  EXPECT_EQ(files[0].filename(), "imubridge-20240521-143000.db");
}

}  // namespace
}  // namespace imubridge::daemon
