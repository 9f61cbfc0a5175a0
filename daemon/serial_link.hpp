#pragma once
// One serial port of `imubridge run`: opened by path or USB identity, read asynchronously, and reopened whenever it
// vanishes (USB unplugged, radio reset, pty closed) or is not there yet: at once when its directory shows a change
// (DeviceWatch), else with exponential backoff. Reading goes on for as long as the link exists: no failure of the
// port is ever final. It never reads another program's terminal: not a controlling terminal, and after a loss not
// the tty a symlink still names unless the symlink was pointed anew or the tty is the very node it was.
#include <sys/stat.h>

#include <array>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "daemon/asio.hpp"
#include "daemon/config.hpp"
#include "daemon/device_watch.hpp"

namespace imubridge::daemon {

class SerialLink {
 public:
  struct Handlers {
    // Bytes exactly as one read returned them.
    std::function<void(std::span<const std::uint8_t>)> on_data;
    // The port is open: `path` is what the device resolved to; `reopened` after a loss, not on the first open.
    std::function<void(const std::string& path, bool reopened)> on_open;
    // The open port failed (read error or end of file); reconnecting starts.
    std::function<void(const std::string& reason)> on_lost;
  };
  struct Counters {
    std::uint64_t bytes_read = 0, reads = 0;
    std::uint64_t bytes_written = 0, bytes_dropped_tx = 0;  // tx: dropped when closed or the queue is full
    std::uint64_t opens = 0, losses = 0, failed_opens = 0;
    std::size_t tx_queue_bytes = 0;
  };
  // Bytes waiting to be written beyond which writes are dropped: a port that cannot keep up must not hold memory.
  static constexpr std::size_t kMaxTxQueueBytes = 64 * 1024;

  SerialLink(boost::asio::io_context& io, const LinkConfig& config, Handlers handlers);
  SerialLink(const SerialLink&) = delete;
  SerialLink& operator=(const SerialLink&) = delete;

  void start();  // the first open is attempted at once; failure is logged once and retried like a loss
  void stop();   // closes the port; no handler is called after this
  // Never blocks. Returns false (and counts the bytes) when they are dropped: port closed or queue full.
  bool write(std::span<const std::uint8_t> bytes);

  bool is_open() const { return port_.is_open(); }
  const std::string& path() const { return path_; }  // the device's path while open
  const Counters& counters() const { return counters_; }

 private:
  void try_open();
  void open(const std::string& path);
  // Throws ForeignTerminal (a std::runtime_error) when the configured symlink still names what it named at the loss,
  // but the node there is no longer the one that was open: a freed pty that another program may have been given since.
  void refuse_stale_symlink() const;
  void read();
  void lost(const std::string& reason);
  void retry_later();
  void write_next();

  const LinkConfig config_;
  Handlers handlers_;
  boost::asio::serial_port port_;
  boost::asio::steady_timer retry_timer_;
  std::chrono::milliseconds backoff_;
  bool stopped_ = true;
  bool ever_opened_ = false;
  bool failure_logged_ = false;  // one log line per outage, however many attempts it takes
  bool refusal_logged_ = false;  // the same for a tty refused as another program's
  std::string path_;
  // Identities while open: the configured path's own (lstat; a symlink's inode and change time) and the node read.
  struct Identity {
    dev_t dev = 0;
    ino_t ino = 0;
    timespec ctime{};
    dev_t rdev = 0;  // 0 for a symlink
    static Identity of(const struct stat& s) { return {s.st_dev, s.st_ino, s.st_ctim, s.st_rdev}; }
    bool operator==(const Identity& o) const {
      return dev == o.dev && ino == o.ino && ctime.tv_sec == o.ctime.tv_sec && ctime.tv_nsec == o.ctime.tv_nsec &&
             rdev == o.rdev;
    }
  };
  std::optional<Identity> opened_symlink_, opened_node_;
  std::unique_ptr<DeviceWatch> watch_;
  std::array<std::uint8_t, 4096> buffer_{};
  std::deque<std::vector<std::uint8_t>> tx_queue_;
  bool writing_ = false;
  Counters counters_;
};

}  // namespace imubridge::daemon
