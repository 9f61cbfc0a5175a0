#pragma once
// Tells a link the moment something appears where its device could: inotify on the directories its path (or, for a
// USB identity, the device nodes) would show up in. A reconnect then starts at once instead of waiting out its
// backoff. Directories that do not exist are skipped; a watch that cannot be set up leaves the backoff alone.
#include <array>
#include <filesystem>
#include <functional>
#include <utility>
#include <vector>

#include "daemon/asio.hpp"

namespace imubridge::daemon {

class DeviceWatch {
 public:
  // `on_change` runs on the io_context for every batch of entries created, moved in or changed in `directories`.
  DeviceWatch(const boost::asio::any_io_executor& executor, const std::vector<std::filesystem::path>& directories,
              std::function<void()> on_change);
  ~DeviceWatch();
  DeviceWatch(const DeviceWatch&) = delete;
  DeviceWatch& operator=(const DeviceWatch&) = delete;

  void stop();

 private:
  void read();
  // Watches each wanted directory, or while it does not exist the nearest ancestor that does (its creation is an
  // event, and the next refresh watches it): /dev/serial/by-id only exists while a USB serial device is plugged in.
  void refresh();

  boost::asio::posix::stream_descriptor stream_;
  std::vector<std::filesystem::path> directories_;
  std::function<void()> on_change_;
  std::array<char, 4096> buffer_{};
};

}  // namespace imubridge::daemon
