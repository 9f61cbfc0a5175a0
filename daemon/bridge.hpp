#pragma once
// A link's raw bytes, both ways, between its serial port and network endpoints: imubridge can then sit between a
// telemetry radio and a ground-control station that needs the same port (QGroundControl on udp://127.0.0.1:14550).
// Behaviour per endpoint kind and the counters: docs/outputs.md, "Link bridge".
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <span>
#include <vector>

#include "daemon/asio.hpp"
#include "daemon/config.hpp"
#include "daemon/endpoint.hpp"

namespace imubridge::daemon {

// A ground station that stops reading may fall this far behind before link bytes to it are dropped (seconds of
// telemetry at radio rates).
inline constexpr std::size_t kMaxQueuedBytesPerBridgePeer = 256 * 1024;
// A tcp:// endpoint that is down (or hangs up) is tried again after 200 ms, doubling up to 5 s; a connection attempt
// that gets no answer is abandoned after 5 s.
inline constexpr std::chrono::milliseconds kBridgeReconnectMin{200}, kBridgeReconnectMax{5000};
inline constexpr std::chrono::milliseconds kBridgeConnectTimeout{5000};

// Call every member from the io_context's thread.
class LinkBridge {
 public:
  // udp: sends to host:port and accepts datagrams from exactly that address and port (the station's replies).
  // tcp: connects, and reconnects with backoff. tcp-listen / unix: accepts any number of clients.
  // Listening sockets and UDP sockets bind to the loopback unless the endpoint names another address. Throws
  // std::runtime_error naming the endpoint when a socket cannot be opened.
  LinkBridge(boost::asio::io_context& io, const std::vector<Endpoint>& endpoints,
             std::function<void(std::span<const std::uint8_t>)> to_link);
  ~LinkBridge();
  LinkBridge(const LinkBridge&) = delete;
  LinkBridge& operator=(const LinkBridge&) = delete;

  // Never blocks: bytes a station has no room for are dropped (whole chunks) and counted.
  void from_link(std::span<const std::uint8_t> bytes);
  nlohmann::json counters() const;

  class Port;  // one endpoint

 private:
  std::vector<std::shared_ptr<Port>> ports_;
};

}  // namespace imubridge::daemon
