// How the store says what is wrong: a file it cannot use is named with the reason, and a failure on its background
// checkpoint thread reaches the program's log through the report sink instead of stderr.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <string>
#include <vector>

#include "store/report.hpp"
#include "store/store.hpp"
#include "store/wal_checkpointer.hpp"
#include "tests/support/temp_dir.hpp"

namespace imubridge::store {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using test::TempDir;

std::string open_error(const fs::path& path, bool read_only = false) {
  try {
    Store store(path, {.read_only = read_only});
    return "";
  } catch (const StoreError& e) {
    return e.what();
  }
}

TEST(StoreErrors, AFileThatCannotBeTheDatabaseIsNamedWithTheReason) {
  TempDir dir;
  EXPECT_EQ(open_error(dir.path()), dir.path().string() + ": is a directory, not a database file");
  EXPECT_EQ(open_error(dir.path(), true), dir.path().string() + ": is a directory, not a database file");
  EXPECT_EQ(open_error(dir / "missing/x.db"),
            (dir / "missing/x.db").string() + ": its directory " + (dir / "missing").string() + " does not exist");
  EXPECT_EQ(open_error(dir / "x.db"), "") << "a new database in an existing directory";
}

// Root may write any file it can open, except an immutable one: that stands in for a read-only file there.
TEST(StoreErrors, AReadOnlyFileIsRefusedForRecordingAndStillRead) {
  TempDir dir;
  const fs::path path = dir / "x.db";
  { Store store(path); }
  fs::permissions(path, fs::perms::owner_read | fs::perms::group_read | fs::perms::others_read);
  struct Immutable {
    std::string path;
    bool set = false;
    ~Immutable() {
      if (set) (void)std::system(("chattr -i '" + path + "'").c_str());
    }
  } immutable{path.string()};
  if (::geteuid() == 0) {
    immutable.set = std::system(("chattr +i '" + path.string() + "' 2>/dev/null").c_str()) == 0;
    if (!immutable.set) GTEST_SKIP() << "running as root, and this file system has no immutable files";
  }
  const std::string error = open_error(path);
  EXPECT_EQ(error.rfind(path.string() + ": not writable (", 0), 0u) << error;
  EXPECT_EQ(error.find('\n'), std::string::npos) << error;
  EXPECT_EQ(open_error(path, true), "");
}

// A checkpoint that cannot write the database file (the file size limit stands in for a full disk) is reported once,
// as one line naming the file, to the sink the program set; the next success clears it.
TEST(StoreErrors, AFailedBackgroundCheckpointIsReportedThroughTheSink) {
  TempDir dir;
  const fs::path path = dir / "x.db";
  std::mutex mutex;
  std::vector<std::string> lines;
  set_report_sink([&](std::string_view line) {
    const std::lock_guard lock(mutex);
    lines.emplace_back(line);
  });
  {
    Store store(path);
    const std::int64_t session = store.begin_session({.kind = "live"});
    const std::int64_t link = store.add_link(session, "imu0", "imubridge", "");
    const std::vector<std::uint8_t> bytes(4096, 0x5a);
    for (int i = 0; i < 64; ++i) store.append_chunk(session, link, Direction::rx, i, i, bytes);
    store.commit();
    WalCheckpointer checkpointer(path, 1h);  // checkpoints only when asked here

    rlimit unlimited{};
    ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &unlimited), 0);
    const rlimit at_current_size{static_cast<rlim_t>(fs::file_size(path)), unlimited.rlim_max};
    const auto previous_handler = ::signal(SIGXFSZ, SIG_IGN);  // a write past the limit fails instead of killing
    ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &at_current_size), 0);
    checkpointer.checkpoint();
    checkpointer.checkpoint();
    ::setrlimit(RLIMIT_FSIZE, &unlimited);
    ::signal(SIGXFSZ, previous_handler);
    checkpointer.checkpoint();
  }
  set_report_sink({});
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0].rfind(path.string() + ": background checkpoint failed: ", 0), 0u) << lines[0];
  EXPECT_EQ(lines[0].find('\n'), std::string::npos) << lines[0];
}

// A destructor cannot throw: the commit it makes reports its failure through the same sink.
TEST(StoreErrors, ACommitFailingInTheDestructorIsReportedThroughTheSink) {
  TempDir dir;
  const fs::path path = dir / "x.db";
  std::vector<std::string> lines;
  set_report_sink([&](std::string_view line) { lines.emplace_back(line); });
  rlimit unlimited{};
  ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &unlimited), 0);
  const auto previous_handler = ::signal(SIGXFSZ, SIG_IGN);
  {
    Store store(path);
    const std::int64_t session = store.begin_session({.kind = "live"});
    const std::int64_t link = store.add_link(session, "imu0", "imubridge", "");
    const std::vector<std::uint8_t> bytes(4096, 0x5a);
    for (int i = 0; i < 64; ++i) store.append_chunk(session, link, Direction::rx, i, i, bytes);
    const rlimit at_current_size{static_cast<rlim_t>(fs::file_size(dir / "x.db-wal")), unlimited.rlim_max};
    ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &at_current_size), 0);
  }
  ::setrlimit(RLIMIT_FSIZE, &unlimited);
  ::signal(SIGXFSZ, previous_handler);
  set_report_sink({});
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0].rfind(path.string() + ": ", 0), 0u) << lines[0];
  EXPECT_NE(lines[0].find("rolled back the 64 rows"), std::string::npos) << lines[0];
}

}  // namespace
}  // namespace imubridge::store
