#include "daemon/serial_link.hpp"

#include <linux/serial.h>
#include <spdlog/spdlog.h>
#include <sys/ioctl.h>

#include <algorithm>
#include <boost/asio/write.hpp>
#include <filesystem>

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

}  // namespace

SerialLink::SerialLink(asio::io_context& io, const LinkConfig& config, Handlers handlers)
    : config_(config), handlers_(std::move(handlers)), port_(io), retry_timer_(io), backoff_(config.reconnect_min) {}

void SerialLink::start() {
  stopped_ = false;
  try_open();
}

void SerialLink::stop() {
  stopped_ = true;
  retry_timer_.cancel();
  boost::system::error_code ignored;
  port_.close(ignored);
}

void SerialLink::try_open() {
  std::string path;
  try {
    path = resolve(config_.device, config_.device.usb_vid ? list_ports() : std::vector<PortInfo>{}).string();
    open(path);
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
    port_.set_option(asio::serial_port::baud_rate(config_.baud));
    port_.set_option(asio::serial_port::character_size(8));
    port_.set_option(asio::serial_port::parity(asio::serial_port::parity::none));
    port_.set_option(asio::serial_port::stop_bits(asio::serial_port::stop_bits::one));
    port_.set_option(asio::serial_port::flow_control(asio::serial_port::flow_control::none));
  } catch (...) {
    boost::system::error_code ignored;
    port_.close(ignored);
    throw;
  }
  tune(port_.native_handle());
  const bool reopened = ever_opened_;
  ever_opened_ = true;
  path_ = path;
  backoff_ = config_.reconnect_min;
  failure_logged_ = false;
  ++counters_.opens;
  std::error_code ec;
  const std::filesystem::path target = std::filesystem::canonical(path, ec);  // a by-id or pty symlink's tty
  spdlog::info("link '{}': {} {}{}{} at {} baud", config_.name, reopened ? "reconnected to" : "reading", path,
               !ec && target != path ? " -> " + target.string() : "",
               config_.device.usb_vid ? " (" + describe(config_.device) + ")" : "", config_.baud);
  if (handlers_.on_open) handlers_.on_open(path, reopened);
  read();
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
