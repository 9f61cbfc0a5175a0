#include "daemon/device_watch.hpp"

#include <spdlog/spdlog.h>
#include <sys/inotify.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace imubridge::daemon {

DeviceWatch::DeviceWatch(const boost::asio::any_io_executor& executor,
                         const std::vector<std::filesystem::path>& directories, std::function<void()> on_change)
    : stream_(executor), directories_(directories), on_change_(std::move(on_change)) {
  const int fd = ::inotify_init1(IN_NONBLOCK | IN_CLOEXEC);
  if (fd < 0) {
    spdlog::debug("inotify unavailable ({}): reconnecting on the backoff alone", std::strerror(errno));
    return;
  }
  stream_.assign(fd);
  refresh();
  read();
}

void DeviceWatch::refresh() {
  for (std::filesystem::path dir : directories_) {
    std::error_code ec;
    while (!std::filesystem::is_directory(dir, ec) && dir.has_relative_path()) dir = dir.parent_path();
    // A device node is created, a symlink made or renamed into place, or given its permissions by udev after the
    // node appeared (an open before that fails with EACCES). Adding a watch twice only renews it.
    if (::inotify_add_watch(stream_.native_handle(), dir.c_str(), IN_CREATE | IN_MOVED_TO | IN_ATTRIB) < 0)
      spdlog::debug("cannot watch {} ({})", dir.string(), std::strerror(errno));
  }
}

DeviceWatch::~DeviceWatch() { stop(); }

void DeviceWatch::stop() {
  boost::system::error_code ignored;
  stream_.close(ignored);
}

void DeviceWatch::read() {
  stream_.async_read_some(boost::asio::buffer(buffer_), [this](const boost::system::error_code& ec, std::size_t) {
    if (ec) return;  // closed, or the descriptor failed: the backoff still reconnects
    refresh();
    // What changed does not matter: the link resolves its device anew and decides.
    on_change_();
    read();
  });
}

}  // namespace imubridge::daemon
