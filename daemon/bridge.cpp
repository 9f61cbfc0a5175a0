#include "daemon/bridge.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <string>

#include "daemon/asio.hpp"

namespace imubridge::daemon {

namespace asio = boost::asio;
using boost::system::error_code;
using ToLink = std::function<void(std::span<const std::uint8_t>)>;

class LinkBridge::Port {
 public:
  virtual ~Port() = default;
  virtual void send(const StreamPeer::Message& bytes) = 0;
  virtual void close() = 0;
  // The kind's own counters; "endpoint", "bytes_sent", "bytes_dropped" and "bytes_received" in every kind.
  virtual nlohmann::json counters() const = 0;
};

namespace {

nlohmann::json byte_counters(const Endpoint& endpoint, const StreamPeer::Counters& c) {
  return {{"endpoint", endpoint.text},
          {"bytes_sent", c.bytes_sent},
          {"bytes_dropped", c.bytes_dropped},
          {"bytes_received", c.bytes_received}};
}

// udp://: one datagram per chunk from the link; datagrams from anyone but the target are ignored (and counted).
class UdpPort final : public LinkBridge::Port, public std::enable_shared_from_this<UdpPort> {
 public:
  UdpPort(asio::io_context& io, const Endpoint& endpoint, ToLink to_link)
      : endpoint_(endpoint),
        socket_(open_udp(io, endpoint)),
        target_(udp_address(endpoint)),
        to_link_(std::move(to_link)) {}

  void receive() {
    socket_.async_receive_from(
        asio::buffer(buffer_), sender_, [self = shared_from_this()](error_code ec, std::size_t n) {
          if (!self->open_) return;
          if (ec) {
            ++self->receive_errors_;  // unconnected UDP sockets report no ICMP errors, so this concerns one datagram
          } else if (self->sender_ != self->target_) {
            ++self->datagrams_ignored_;
          } else {
            self->counters_.bytes_received += n;
            self->to_link_(std::span(self->buffer_).first(n));
          }
          if (self->open_) self->receive();
        });
  }

  void send(const StreamPeer::Message& bytes) override {
    error_code ec;  // a full send buffer (the socket does not block) drops the datagram
    socket_.send_to(asio::buffer(*bytes), target_, 0, ec);
    (ec ? counters_.bytes_dropped : counters_.bytes_sent) += bytes->size();
  }

  void close() override {
    open_ = false;
    error_code ignored;
    socket_.close(ignored);
  }

  nlohmann::json counters() const override {
    auto j = byte_counters(endpoint_, counters_);
    j["datagrams_ignored"] = datagrams_ignored_;
    j["receive_errors"] = receive_errors_;
    return j;
  }

 private:
  Endpoint endpoint_;
  asio::ip::udp::socket socket_;
  asio::ip::udp::endpoint target_, sender_;
  ToLink to_link_;
  bool open_ = true;
  std::array<std::uint8_t, 65536> buffer_{};
  StreamPeer::Counters counters_;
  std::uint64_t datagrams_ignored_ = 0, receive_errors_ = 0;
};

// tcp://: one connection, made again whenever it fails. Link bytes while it is down reach nobody, like a station
// that is not running; they are not counted as dropped.
class ConnectPort final : public LinkBridge::Port, public std::enable_shared_from_this<ConnectPort> {
 public:
  ConnectPort(asio::io_context& io, const Endpoint& endpoint, ToLink to_link)
      : endpoint_(endpoint),
        address_(asio::ip::tcp::endpoint(asio::ip::make_address(endpoint.host), endpoint.port)),
        socket_(io),
        retry_(io),
        deadline_(io),
        to_link_(std::move(to_link)) {}

  void connect() {
    socket_ = StreamSocket(retry_.get_executor());
    socket_.async_connect(address_, [self = shared_from_this()](const error_code& ec) {
      if (!self->open_) return;
      self->deadline_.cancel();
      if (ec) {
        ++self->connect_failures_;
        return self->retry();
      }
      ++self->connects_;
      self->backoff_ = kBridgeReconnectMin;
      spdlog::info("{}: connected", self->endpoint_.text);
      self->peer_ = StreamPeer::start(std::move(self->socket_), kMaxQueuedBytesPerBridgePeer, self->to_link_,
                                      [weak = self->weak_from_this()] {
                                        if (auto port = weak.lock()) port->disconnected();
                                      });
    });
    deadline_.expires_after(kBridgeConnectTimeout);
    deadline_.async_wait([self = shared_from_this()](const error_code& ec) {
      error_code ignored;
      if (!ec && self->open_) self->socket_.close(ignored);  // the connect handler then counts a failure
    });
  }

  void send(const StreamPeer::Message& bytes) override {
    if (peer_) peer_->send(bytes);
  }

  void close() override {
    open_ = false;
    error_code ignored;
    socket_.close(ignored);
    retry_.cancel();
    deadline_.cancel();
    if (peer_) peer_->close();
  }

  nlohmann::json counters() const override {
    StreamPeer::Counters c = past_;
    if (peer_) c += peer_->counters();
    auto j = byte_counters(endpoint_, c);
    j["connected"] = peer_ != nullptr;
    j["connects"] = connects_;
    j["connect_failures"] = connect_failures_;
    return j;
  }

 private:
  void disconnected() {
    spdlog::warn("{}: connection lost; reconnecting", endpoint_.text);
    past_ += peer_->counters();
    peer_.reset();
    retry();
  }

  void retry() {
    retry_.expires_after(backoff_);
    backoff_ = std::min(2 * backoff_, kBridgeReconnectMax);
    retry_.async_wait([self = shared_from_this()](const error_code& ec) {
      if (!ec && self->open_) self->connect();
    });
  }

  Endpoint endpoint_;
  asio::generic::stream_protocol::endpoint address_;
  StreamSocket socket_;  // the connection being made
  asio::steady_timer retry_, deadline_;
  ToLink to_link_;
  bool open_ = true;
  std::chrono::milliseconds backoff_ = kBridgeReconnectMin;
  std::shared_ptr<StreamPeer> peer_;  // the connection made
  StreamPeer::Counters past_;         // of the connections before it
  std::uint64_t connects_ = 0, connect_failures_ = 0;
};

// tcp-listen:// and unix://: every client gets the link's bytes, and whatever any client sends goes to the link.
class ServerPort final : public LinkBridge::Port {
 public:
  ServerPort(asio::io_context& io, const Endpoint& endpoint, ToLink to_link)
      : server_(StreamServer::start(io, endpoint, kMaxQueuedBytesPerBridgePeer, std::move(to_link))) {}

  void send(const StreamPeer::Message& bytes) override { server_->send(bytes); }
  void close() override { server_->close(); }

  nlohmann::json counters() const override {
    auto j = byte_counters(server_->endpoint(), server_->totals());
    if (server_->endpoint().kind == Endpoint::Kind::tcp_listen) j["port"] = server_->port();
    j["accepted"] = server_->accepted();
    j["clients"] = server_->clients().size();
    return j;
  }

 private:
  std::shared_ptr<StreamServer> server_;
};

}  // namespace

LinkBridge::LinkBridge(asio::io_context& io, const std::vector<Endpoint>& endpoints, ToLink to_link) {
  try {
    for (const Endpoint& endpoint : endpoints) {
      switch (endpoint.kind) {
        case Endpoint::Kind::udp: {
          auto port = std::make_shared<UdpPort>(io, endpoint, to_link);
          port->receive();
          ports_.push_back(std::move(port));
          break;
        }
        case Endpoint::Kind::tcp_connect: {
          auto port = std::make_shared<ConnectPort>(io, endpoint, to_link);
          port->connect();
          ports_.push_back(std::move(port));
          break;
        }
        case Endpoint::Kind::tcp_listen:
        case Endpoint::Kind::unix_listen:
          ports_.push_back(std::make_shared<ServerPort>(io, endpoint, to_link));
          break;
      }
    }
  } catch (...) {
    for (const auto& port : ports_) port->close();
    throw;
  }
}

LinkBridge::~LinkBridge() {
  for (const auto& port : ports_) port->close();
}

void LinkBridge::from_link(std::span<const std::uint8_t> bytes) {
  if (ports_.empty() || bytes.empty()) return;
  const auto message = std::make_shared<const std::string>(bytes.begin(), bytes.end());
  for (const auto& port : ports_) port->send(message);
}

nlohmann::json LinkBridge::counters() const {
  nlohmann::json j = nlohmann::json::array();
  for (const auto& port : ports_) j.push_back(port->counters());
  return j;
}

}  // namespace imubridge::daemon
