#include "daemon/serial_link.hpp"

#include <dirent.h>
#include <linux/serial.h>
#include <spdlog/spdlog.h>
#include <sys/ioctl.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "daemon/asio.hpp"
#include "daemon/port_list.hpp"

namespace imubridge::daemon {
namespace {

namespace asio = boost::asio;

// Best effort, so pseudo-terminals and drivers without these ioctls work as well.
void tune(int fd) {
  // No other program (ModemManager probing a radio, a second imubridge) may open the port while we read it.
  ::ioctl(fd, TIOCEXCL);
  // USB serial drivers (FTDI) otherwise hold received bytes for up to 16 ms before handing them over.
  serial_struct serial{};
  if (::ioctl(fd, TIOCGSERIAL, &serial) == 0 && !(serial.flags & ASYNC_LOW_LATENCY)) {
    serial.flags |= ASYNC_LOW_LATENCY;
    ::ioctl(fd, TIOCSSERIAL, &serial);
  }
}

// A tty that may be another program's: refused, and said once per outage whatever else was logged.
struct ForeignTerminal : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// The process whose session has this tty as its controlling terminal (a shell, an editor), as "PID (name)": such a
// tty is someone's terminal, not a device. Read from /proc; processes it hides (hidepid) are not seen.
std::optional<std::string> controlling_process(dev_t tty) {
  // /proc/PID/stat's tty_nr encodes the device as the kernel's new_encode_dev does.
  const unsigned major_number = major(tty), minor_number = minor(tty);
  const unsigned long tty_nr = (minor_number & 0xffu) | (major_number << 8) | ((minor_number & ~0xffu) << 12);
  const std::string self = std::to_string(::getpid());
  DIR* proc = ::opendir("/proc");
  if (!proc) return std::nullopt;
  std::optional<std::string> found;
  while (const dirent* entry = ::readdir(proc)) {
    const std::string pid = entry->d_name;
    if (pid.empty() || pid.find_first_not_of("0123456789") != std::string::npos || pid == self) continue;
    std::ifstream in("/proc/" + pid + "/stat");
    std::string stat;
    if (!std::getline(in, stat)) continue;
    // "pid (comm) state ppid pgrp session tty_nr ...": comm may hold spaces and parentheses, so from the last ')'.
    const auto open_paren = stat.find('('), close_paren = stat.rfind(')');
    if (open_paren == std::string::npos || close_paren == std::string::npos) continue;
    std::istringstream fields(stat.substr(close_paren + 1));
    std::string state;
    long ppid = 0, pgrp = 0, session = 0;
    unsigned long nr = 0;
    if (!(fields >> state >> ppid >> pgrp >> session >> nr) || nr != tty_nr) continue;
    found = pid + " (" + stat.substr(open_paren + 1, close_paren - open_paren - 1) + ")";
    break;
  }
  ::closedir(proc);
  return found;
}

}  // namespace

SerialLink::SerialLink(asio::io_context& io, const LinkConfig& config, Handlers handlers)
    : config_(config), handlers_(std::move(handlers)), port_(io), retry_timer_(io), backoff_(config.reconnect_min) {}

void SerialLink::start() {
  stopped_ = false;
  std::vector<std::filesystem::path> directories;
  if (config_.device.usb_vid) {
    directories = {"/dev", "/dev/serial/by-id"};  // the node, then udev's symlinks to it
  } else {
    directories = {std::filesystem::absolute(config_.device.path).parent_path()};
  }
  watch_ = std::make_unique<DeviceWatch>(port_.get_executor(), directories, [this] {
    if (stopped_ || port_.is_open()) return;
    retry_timer_.cancel();  // its wait ends as aborted: this attempt replaces it
    try_open();
  });
  try_open();
}

void SerialLink::stop() {
  stopped_ = true;
  if (watch_) watch_->stop();
  retry_timer_.cancel();
  boost::system::error_code ignored;
  port_.close(ignored);
}

void SerialLink::try_open() {
  std::string path;
  try {
    path = resolve(config_.device, config_.device.usb_vid ? list_ports() : std::vector<PortInfo>{}).string();
    if (!config_.device.usb_vid) refuse_stale_symlink();
    open(path);
  } catch (const ForeignTerminal& e) {
    ++counters_.failed_opens;
    if (!refusal_logged_) spdlog::warn("link '{}': refusing {}: {}", config_.name, path, e.what());
    refusal_logged_ = true;
    retry_later();
  } catch (const std::exception& e) {  // no such port yet, no permission, a baud rate the driver refuses, ...
    ++counters_.failed_opens;
    if (!failure_logged_) {
      spdlog::warn("link '{}': cannot open {}: {}; retrying every {} to {} ms", config_.name, describe(config_.device),
                   e.what(), config_.reconnect_min.count(), config_.reconnect_max.count());
      failure_logged_ = true;
    } else {
      spdlog::debug("link '{}': cannot open {}: {}", config_.name, describe(config_.device), e.what());
    }
    retry_later();
  }
}

void SerialLink::open(const std::string& path) {
  port_.open(path);
  try {
    boost::system::error_code baud_error;
    port_.set_option(asio::serial_port::baud_rate(config_.baud), baud_error);
    if (baud_error) throw std::runtime_error(std::to_string(config_.baud) + " baud: " + baud_error.message());
    port_.set_option(asio::serial_port::character_size(8));
    port_.set_option(asio::serial_port::parity(asio::serial_port::parity::none));
    port_.set_option(asio::serial_port::stop_bits(asio::serial_port::stop_bits::one));
    port_.set_option(asio::serial_port::flow_control(asio::serial_port::flow_control::none));
  } catch (...) {
    boost::system::error_code ignored;
    port_.close(ignored);
    throw;
  }
  struct stat node {};
  if (::fstat(port_.native_handle(), &node) == 0 && S_ISCHR(node.st_mode)) {
    if (const auto owner = controlling_process(node.st_rdev)) {
      boost::system::error_code ignored;
      port_.close(ignored);
      throw ForeignTerminal("it is the controlling terminal of process " + *owner +
                            ", another session's terminal, not a device: not reading it");
    }
  }
  tune(port_.native_handle());
  opened_node_ = Identity::of(node);
  struct stat link {};
  opened_symlink_.reset();
  if (::lstat(config_.device.path.c_str(), &link) == 0 && S_ISLNK(link.st_mode)) opened_symlink_ = Identity::of(link);
  const bool reopened = ever_opened_;
  ever_opened_ = true;
  path_ = path;
  backoff_ = config_.reconnect_min;
  failure_logged_ = refusal_logged_ = false;
  ++counters_.opens;
  std::error_code ec;
  const std::filesystem::path target = std::filesystem::canonical(path, ec);  // a by-id or pty symlink's tty
  spdlog::info("link '{}': {} {}{}{} at {} baud", config_.name, reopened ? "reconnected to" : "reading", path,
               !ec && target != path ? " -> " + target.string() : "",
               config_.device.usb_vid ? " (" + describe(config_.device) + ")" : "", config_.baud);
  if (handlers_.on_open) handlers_.on_open(path, reopened);
  read();
}

void SerialLink::refuse_stale_symlink() const {
  if (!opened_symlink_ || !opened_node_) return;  // never open, or not through a symlink
  struct stat link {};
  if (::lstat(config_.device.path.c_str(), &link) != 0 || !S_ISLNK(link.st_mode)) return;  // made anew
  if (!(Identity::of(link) == *opened_symlink_)) return;                                   // pointed anew
  struct stat node {};
  if (::stat(config_.device.path.c_str(), &node) == 0 && Identity::of(node) == *opened_node_)
    return;  // the very node that was open: the same device, still there
  throw ForeignTerminal(config_.device.path.string() +
                        " still names the tty it named when the device was lost, and that tty was freed since: "
                        "another program may have it now; waiting for the link to be pointed anew");
}

void SerialLink::read() {
  port_.async_read_some(asio::buffer(buffer_), [this](const boost::system::error_code& ec, std::size_t n) {
    if (stopped_ || ec == asio::error::operation_aborted) return;
    if (ec) return lost(ec == asio::error::eof ? std::string("end of file") : ec.message());
    ++counters_.reads;
    counters_.bytes_read += n;
    handlers_.on_data(std::span<const std::uint8_t>(buffer_.data(), n));
    if (!stopped_) read();
  });
}

void SerialLink::lost(const std::string& reason) {
  boost::system::error_code ignored;
  port_.close(ignored);
  ++counters_.losses;
  spdlog::warn("link '{}': lost {} ({}); reconnecting", config_.name, path_, reason);
  failure_logged_ = true;  // this outage is logged: the attempts to reopen stay quiet until one succeeds
  for (const auto& pending : tx_queue_) counters_.bytes_dropped_tx += pending.size();
  tx_queue_.clear();
  counters_.tx_queue_bytes = 0;
  writing_ = false;
  path_.clear();
  if (handlers_.on_lost) handlers_.on_lost(reason);
  if (!stopped_) retry_later();
}

void SerialLink::retry_later() {
  retry_timer_.expires_after(backoff_);
  backoff_ = std::min(backoff_ * 2, config_.reconnect_max);
  retry_timer_.async_wait([this](const boost::system::error_code& ec) {
    if (!ec && !stopped_) try_open();
  });
}

bool SerialLink::write(std::span<const std::uint8_t> bytes) {
  if (!port_.is_open() || counters_.tx_queue_bytes + bytes.size() > kMaxTxQueueBytes) {
    counters_.bytes_dropped_tx += bytes.size();
    return false;
  }
  tx_queue_.emplace_back(bytes.begin(), bytes.end());
  counters_.tx_queue_bytes += bytes.size();
  if (!writing_) write_next();
  return true;
}

void SerialLink::write_next() {
  writing_ = !tx_queue_.empty();
  if (!writing_) return;
  asio::async_write(port_, asio::buffer(tx_queue_.front()), [this](const boost::system::error_code& ec, std::size_t n) {
    if (stopped_ || ec == asio::error::operation_aborted) return;  // lost() or stop() already emptied the queue
    const std::size_t size = tx_queue_.front().size();
    counters_.tx_queue_bytes -= size;
    if (ec) {
      counters_.bytes_dropped_tx += size;  // the read side notices a vanished port and reconnects
    } else {
      counters_.bytes_written += n;
    }
    tx_queue_.pop_front();
    write_next();
  });
}

}  // namespace imubridge::daemon
