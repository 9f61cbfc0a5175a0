#include "daemon/pty.hpp"

#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <system_error>

namespace imubridge::cli {

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
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && errno == EAGAIN) {
      // Give a reader a moment to drain the buffer before treating the bytes as lost on the line.
      pollfd pfd{master_, POLLOUT, 0};
      if (::poll(&pfd, 1, 20) > 0) continue;
      dropped_ += bytes.size();
      return;
    }
    throw std::system_error(errno, std::generic_category(), "write to pty " + slave_name_);
  }
}

}  // namespace imubridge::cli
