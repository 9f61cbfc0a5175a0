#include "cli/pty.hpp"

#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <sys/ioctl.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <system_error>
#include <thread>

namespace imubridge::cli {

namespace {

// How long a writer waits for a reader that keeps up to make room, like a UART's FIFO absorbing a short hiccup.
constexpr int kRoomWaitMs = 20;
// The slave's input queue (FIONREAD, the line discipline's 4 KiB) cannot show the pty's own buffer behind it, which
// the kernel moves into the queue from a worker thread after each read. So an empty queue means "all read" only
// once it has stayed empty far longer than that worker takes to run.
constexpr auto kSettle = std::chrono::milliseconds(50);
constexpr auto kPollInterval = std::chrono::milliseconds(2);

std::size_t input_queue_bytes(int slave_fd) {
  int pending = 0;
  if (::ioctl(slave_fd, FIONREAD, &pending) != 0) return 0;
  return static_cast<std::size_t>(pending);
}

}  // namespace

PtyPair::PtyPair(std::filesystem::path link_path) : link_path_(std::move(link_path)) {
  char name[256] = {};
  termios raw{};
  cfmakeraw(&raw);  // bytes pass untouched: no echo, no CR/LF translation, no signals
  if (openpty(&master_, &slave_, name, &raw, nullptr) != 0) {
    throw std::system_error(errno, std::generic_category(), "openpty");
  }
  slave_name_ = name;
  const int flags = fcntl(master_, F_GETFL);
  fcntl(master_, F_SETFL, flags | O_NONBLOCK);
  std::error_code ec;
  if (std::filesystem::is_symlink(std::filesystem::symlink_status(link_path_, ec))) {
    std::filesystem::remove(link_path_, ec);
  } else if (std::filesystem::exists(link_path_, ec)) {
    ::close(master_);
    ::close(slave_);
    throw std::runtime_error(link_path_.string() + " exists and is not a symlink; refusing to replace it");
  }
  std::filesystem::create_symlink(slave_name_, link_path_);
}

PtyPair::~PtyPair() {
  std::error_code ec;
  if (std::filesystem::read_symlink(link_path_, ec) == slave_name_) std::filesystem::remove(link_path_, ec);
  ::close(master_);
  ::close(slave_);
}

void PtyPair::write(std::span<const std::uint8_t> bytes) {
  while (!bytes.empty()) {
    const ssize_t n = ::write(master_, bytes.data(), bytes.size());
    if (n > 0) {
      bytes = bytes.subspan(static_cast<std::size_t>(n));
      reader_behind_ = false;
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && errno == EAGAIN) {
      // Only a reader that has kept up gets the wait: with nobody reading, every write would pay it.
      pollfd pfd{master_, POLLOUT, 0};
      if (::poll(&pfd, 1, reader_behind_ ? 0 : kRoomWaitMs) > 0) continue;
      dropped_ += bytes.size();
      reader_behind_ = true;
      return;
    }
    throw std::system_error(errno, std::generic_category(), "write to pty " + slave_name_);
  }
}

std::size_t PtyPair::drain(std::chrono::milliseconds patience) {
  // tcdrain() returns at once on a pty master (it has no output queue of its own): watch the slave's input queue.
  using Clock = std::chrono::steady_clock;
  auto give_up = Clock::now() + patience;
  std::optional<Clock::time_point> empty_since;
  std::size_t before = input_queue_bytes(slave_);
  for (;;) {
    const auto now = Clock::now();
    const std::size_t pending = input_queue_bytes(slave_);
    if (pending == 0) {
      if (!empty_since) empty_since = now;
      if (now - *empty_since >= kSettle) return 0;
    } else {
      empty_since.reset();
    }
    if (pending != before) give_up = now + patience;  // the reader is still reading
    before = pending;
    if (now >= give_up && pending > 0) return pending;
    std::this_thread::sleep_for(kPollInterval);
  }
}

}  // namespace imubridge::cli
