// cli::PtyPair, the pseudo-terminal that `imubridge sim --pty`, `replay --to-pty` and the daemon tests write into:
// what a reader on the slave gets, what is dropped when nobody reads, and that drain() keeps the tail from being
// discarded when the pair closes.
#include "cli/pty.hpp"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "tests/support/temp_dir.hpp"

namespace imubridge::cli {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

class PtyTest : public ::testing::Test {
 protected:
  // A byte pattern that shows any loss, duplication or reordering.
  static std::vector<std::uint8_t> pattern(std::size_t size) {
    std::vector<std::uint8_t> bytes(size);
    for (std::size_t i = 0; i < size; ++i) bytes[i] = static_cast<std::uint8_t>((i * 7 + i / 251) % 256);
    return bytes;
  }
  int open_slave() const { return ::open((dir_ / "tty").c_str(), O_RDONLY | O_NOCTTY); }
  // Everything readable from `fd` until it ends (the pair closed) or stays silent for `quiet`.
  static std::vector<std::uint8_t> read_until_quiet(int fd, std::chrono::milliseconds quiet) {
    std::vector<std::uint8_t> got;
    std::uint8_t buffer[4096];
    for (pollfd pfd{fd, POLLIN, 0}; ::poll(&pfd, 1, static_cast<int>(quiet.count())) > 0;) {
      const ssize_t n = ::read(fd, buffer, sizeof buffer);
      if (n <= 0) break;
      got.insert(got.end(), buffer, buffer + n);
    }
    return got;
  }

  test::TempDir dir_;
};

TEST_F(PtyTest, DrainWaitsForASlowReaderSoClosingLosesNoByte) {
  // More than the slave's 4 KiB input queue, so part of it waits in the pty's buffer where FIONREAD cannot see it;
  // less than both together, so nothing is dropped before the reader starts.
  const auto sent = pattern(10'000);
  auto pty = std::make_unique<PtyPair>(dir_ / "tty");
  const int fd = open_slave();
  ASSERT_GE(fd, 0);
  pty->write(sent);
  ASSERT_EQ(pty->dropped_bytes(), 0u);

  std::vector<std::uint8_t> got;
  std::thread reader([&] {
    std::uint8_t buffer[64];
    for (;;) {  // 64 bytes a millisecond at best: far slower than the writer
      const ssize_t n = ::read(fd, buffer, sizeof buffer);
      if (n <= 0) break;  // end of file or EIO: the pair was closed
      got.insert(got.end(), buffer, buffer + n);
      std::this_thread::sleep_for(1ms);
    }
  });
  EXPECT_EQ(pty->drain(), 0u);
  pty.reset();  // hangs the slave up: anything still unread now would be lost
  reader.join();
  ::close(fd);
  EXPECT_EQ(got.size(), sent.size());
  EXPECT_EQ(got, sent);
}

TEST_F(PtyTest, DrainGivesUpOnAReaderThatReadsNothing) {
  PtyPair pty(dir_ / "tty");
  const int fd = open_slave();  // open, but never read
  ASSERT_GE(fd, 0);
  pty.write(pattern(3000));
  const std::size_t unread = pty.drain(30ms);
  EXPECT_GT(unread, 0u);
  EXPECT_LE(unread, 3000u);
  ::close(fd);
}

TEST_F(PtyTest, BytesThatDoNotFitAreDroppedAndCountedAndTheRestArrivesInOrder) {
  PtyPair pty(dir_ / "tty");
  const auto first = pattern(256 * 1024);  // far more than a pty holds
  pty.write(first);
  const std::uint64_t dropped_first = pty.dropped_bytes();
  ASSERT_GT(dropped_first, 0u);
  ASSERT_LT(dropped_first, first.size());
  pty.write(pattern(1000));  // still nobody reading: all of it dropped, without waiting for room
  EXPECT_EQ(pty.dropped_bytes(), dropped_first + 1000);

  const int fd = open_slave();
  ASSERT_GE(fd, 0);
  const auto got = read_until_quiet(fd, 200ms);
  ::close(fd);
  const std::vector<std::uint8_t> kept(first.begin(), first.end() - static_cast<std::ptrdiff_t>(dropped_first));
  EXPECT_EQ(got, kept) << "what was not dropped is the stream's beginning, whole";
}

TEST_F(PtyTest, TheSymlinkPointsAtTheSlaveAndGoesWithThePair) {
  {
    PtyPair pty(dir_ / "tty");
    EXPECT_EQ(fs::read_symlink(dir_ / "tty"), pty.slave_name());
  }
  EXPECT_FALSE(fs::exists(fs::symlink_status(dir_ / "tty")));
  std::ofstream(dir_ / "file") << "not a link";
  EXPECT_THROW(PtyPair(dir_ / "file"), std::runtime_error);
}

}  // namespace
}  // namespace imubridge::cli
