#include "daemon/endpoint.hpp"

#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <sys/un.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include "daemon/asio.hpp"

namespace imubridge::daemon {
namespace {

namespace asio = boost::asio;
using boost::system::error_code;
using GenericEndpoint = asio::generic::stream_protocol::endpoint;
using Acceptor = asio::basic_socket_acceptor<asio::generic::stream_protocol>;

constexpr std::string_view kForms = "udp://host:port, tcp://host:port, tcp-listen://host:port or unix:///path";

std::uint16_t parse_port(std::string_view text, const auto& fail) {
  unsigned value = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (text.empty() || ec != std::errc() || end != text.data() + text.size() || value > 65535) {
    throw fail("port '" + std::string(text) + "' is not a number from 0 to 65535");
  }
  return static_cast<std::uint16_t>(value);
}

GenericEndpoint stream_address(const Endpoint& endpoint) {
  if (endpoint.kind == Endpoint::Kind::unix_listen) return asio::local::stream_protocol::endpoint(endpoint.path);
  return asio::ip::tcp::endpoint(asio::ip::make_address(endpoint.host), endpoint.port);
}

void open_listener(Acceptor& acceptor, const Endpoint& endpoint, const GenericEndpoint& address, error_code& ec) {
  acceptor.close(ec);
  acceptor.open(address.protocol(), ec);
  if (!ec && address.protocol().family() != AF_UNIX) acceptor.set_option(asio::socket_base::reuse_address(true), ec);
  if (!ec) acceptor.bind(address, ec);
  // Before listen(), so that nobody connects while the umask's mode (0755 under the usual 022) still holds.
  if (!ec && endpoint.kind == Endpoint::Kind::unix_listen && ::chmod(endpoint.path.c_str(), kUnixSocketMode) != 0) {
    ec.assign(errno, boost::system::system_category());
  }
  if (!ec) acceptor.listen(asio::socket_base::max_listen_connections, ec);
}

// A unix socket file whose listener is gone refuses connections; a live one accepts them.
bool is_stale_socket(asio::io_context& io, const std::filesystem::path& path) {
  asio::local::stream_protocol::socket probe(io);
  error_code ec;
  probe.connect(asio::local::stream_protocol::endpoint(path), ec);
  return ec == asio::error::connection_refused;
}

}  // namespace

Endpoint parse_endpoint(std::string_view text) {
  const auto fail = [text](const std::string& what) {
    return std::invalid_argument("endpoint '" + std::string(text) + "': " + what);
  };
  const auto scheme_end = text.find("://");
  if (scheme_end == std::string_view::npos) throw fail("expected " + std::string(kForms));
  const std::string_view scheme = text.substr(0, scheme_end);
  const std::string_view rest = text.substr(scheme_end + 3);

  Endpoint e;
  e.text = text;
  if (scheme == "unix") {
    e.kind = Endpoint::Kind::unix_listen;
    if (rest.empty() || rest.front() != '/') throw fail("the path must be absolute, as in unix:///run/imubridge.sock");
    if (rest.size() >= sizeof(sockaddr_un::sun_path)) {
      throw fail("the path is longer than a unix socket allows (" + std::to_string(sizeof(sockaddr_un::sun_path) - 1) +
                 " bytes)");
    }
    e.path = rest;
    return e;
  }
  if (scheme == "udp") {
    e.kind = Endpoint::Kind::udp;
  } else if (scheme == "tcp") {
    e.kind = Endpoint::Kind::tcp_connect;
  } else if (scheme == "tcp-listen") {
    e.kind = Endpoint::Kind::tcp_listen;
  } else {
    throw fail("unknown scheme '" + std::string(scheme) + "' (expected " + std::string(kForms) + ")");
  }

  std::string_view host, port;
  if (rest.starts_with('[')) {
    const auto close = rest.find(']');
    if (close == std::string_view::npos) throw fail("'[' without ']' around the IPv6 address");
    host = rest.substr(1, close - 1);
    if (!rest.substr(close + 1).starts_with(':')) throw fail("no port (expected host:port)");
    port = rest.substr(close + 2);
  } else {
    const auto colon = rest.find(':');
    if (colon == std::string_view::npos) throw fail("no port (expected host:port)");
    if (rest.find(':', colon + 1) != std::string_view::npos) {
      throw fail("an IPv6 address goes in brackets, as in " + std::string(scheme) + "://[::1]:5760");
    }
    host = rest.substr(0, colon);
    port = rest.substr(colon + 1);
  }
  if (host.empty()) throw fail("no host (expected host:port)");
  error_code ec;
  const auto address = asio::ip::make_address(host == "localhost" ? "127.0.0.1" : std::string(host), ec);
  if (ec) {
    throw fail("host '" + std::string(host) + "' is not an IP address (names other than localhost are not resolved)");
  }
  if (rest.starts_with('[') != address.is_v6()) throw fail("brackets go around IPv6 addresses, and only those");
  e.host = address.to_string();
  e.port = parse_port(port, fail);
  if (e.port == 0 && e.kind != Endpoint::Kind::tcp_listen) throw fail("port 0 is only for tcp-listen");
  return e;
}

bool same_address(const Endpoint& a, const Endpoint& b) {
  return a.kind == b.kind && a.host == b.host && a.port == b.port && a.path == b.path;
}

// --- StreamPeer ---

StreamPeer::Counters& StreamPeer::Counters::operator+=(const Counters& other) {
  messages_sent += other.messages_sent;
  bytes_sent += other.bytes_sent;
  messages_dropped += other.messages_dropped;
  bytes_dropped += other.bytes_dropped;
  messages_queued += other.messages_queued;
  bytes_queued += other.bytes_queued;
  bytes_received += other.bytes_received;
  return *this;
}

StreamPeer::StreamPeer(StreamSocket socket, std::size_t max_queued_bytes, OnRead on_read,
                       std::function<void()> on_closed)
    : socket_(std::move(socket)),
      max_queued_bytes_(max_queued_bytes),
      on_read_(std::move(on_read)),
      on_closed_(std::move(on_closed)) {}

std::shared_ptr<StreamPeer> StreamPeer::start(StreamSocket socket, std::size_t max_queued_bytes, OnRead on_read,
                                              std::function<void()> on_closed) {
  std::shared_ptr<StreamPeer> peer(
      new StreamPeer(std::move(socket), max_queued_bytes, std::move(on_read), std::move(on_closed)));
  peer->read();
  return peer;
}

void StreamPeer::send(const Message& message) {
  if (!open_ || counters_.bytes_queued + message->size() > max_queued_bytes_) {
    ++counters_.messages_dropped;
    counters_.bytes_dropped += message->size();
    return;
  }
  ++counters_.messages_queued;
  counters_.bytes_queued += message->size();
  pending_.push_back(message);
  if (writing_.empty()) write();
}

void StreamPeer::write() {
  writing_.swap(pending_);
  buffers_.clear();
  for (const auto& message : writing_) buffers_.push_back(asio::buffer(*message));
  asio::async_write(socket_, buffers_, [self = shared_from_this()](const error_code& ec, std::size_t bytes) {
    if (!self->open_) return;
    if (ec) return self->fail();
    self->counters_.messages_sent += self->writing_.size();
    self->counters_.bytes_sent += bytes;
    self->counters_.messages_queued -= self->writing_.size();
    self->counters_.bytes_queued -= bytes;
    self->writing_.clear();
    if (!self->pending_.empty()) self->write();
  });
}

void StreamPeer::read() {
  socket_.async_read_some(asio::buffer(read_buffer_), [self = shared_from_this()](const error_code& ec, std::size_t n) {
    if (!self->open_) return;
    if (ec) return self->fail();
    self->counters_.bytes_received += n;
    if (self->on_read_) self->on_read_(std::span(self->read_buffer_).first(n));
    if (self->open_) self->read();  // on_read may have closed us
  });
}

void StreamPeer::close() {
  if (!open_) return;
  open_ = false;
  on_read_ = {};
  on_closed_ = {};
  error_code ignored;
  socket_.close(ignored);
  // What was still queued will never be written.
  counters_.messages_dropped += counters_.messages_queued;
  counters_.bytes_dropped += counters_.bytes_queued;
  counters_.messages_queued = counters_.bytes_queued = 0;
  pending_.clear();  // writing_ stays until its (cancelled) write returns
}

void StreamPeer::fail() {
  auto on_closed = std::move(on_closed_);
  close();
  if (on_closed) on_closed();
}

// --- StreamServer ---

StreamServer::StreamServer(asio::io_context& io, const Endpoint& endpoint, std::size_t max_queued_bytes,
                           StreamPeer::OnRead on_read)
    : endpoint_(endpoint),
      acceptor_(io),
      retry_(io),
      max_queued_bytes_(max_queued_bytes),
      on_read_(std::move(on_read)) {
  if (endpoint.kind != Endpoint::Kind::tcp_listen && endpoint.kind != Endpoint::Kind::unix_listen) {
    throw std::invalid_argument(endpoint.text + ": clients connect to tcp-listen:// and unix:// endpoints only");
  }
  const GenericEndpoint address = stream_address(endpoint);
  error_code ec;
  open_listener(acceptor_, endpoint, address, ec);
  if (ec == asio::error::address_in_use && endpoint.kind == Endpoint::Kind::unix_listen) {
    if (!std::filesystem::is_socket(endpoint.path)) {
      throw std::runtime_error(endpoint.text + ": " + endpoint.path.string() + " exists and is not a socket");
    }
    if (!is_stale_socket(io, endpoint.path)) {
      throw std::runtime_error(endpoint.text + ": another process is listening on " + endpoint.path.string());
    }
    std::filesystem::remove(endpoint.path);
    open_listener(acceptor_, endpoint, address, ec);
  }
  if (ec) throw std::runtime_error(endpoint.text + ": cannot listen: " + ec.message());
  if (endpoint.kind == Endpoint::Kind::tcp_listen) {
    // The generic endpoint holds the sockaddr; read its port through the TCP view of the same bytes.
    const GenericEndpoint local = acceptor_.local_endpoint();
    asio::ip::tcp::endpoint tcp;
    std::memcpy(tcp.data(), local.data(), std::min<std::size_t>(local.size(), tcp.capacity()));
    port_ = tcp.port();
  }
}

std::shared_ptr<StreamServer> StreamServer::start(asio::io_context& io, const Endpoint& endpoint,
                                                  std::size_t max_queued_bytes, StreamPeer::OnRead on_read) {
  std::shared_ptr<StreamServer> server(new StreamServer(io, endpoint, max_queued_bytes, std::move(on_read)));
  server->accept();
  return server;
}

void StreamServer::accept() {
  acceptor_.async_accept([self = shared_from_this()](const error_code& ec, StreamSocket socket) {
    if (!self->open_) return;
    if (ec) {
      spdlog::warn("{}: accepting a client failed: {}", self->endpoint_.text, ec.message());
      self->retry_.expires_after(std::chrono::milliseconds(100));
      self->retry_.async_wait([self](const error_code& e) {
        if (!e && self->open_) self->accept();
      });
      return;
    }
    self->prune();
    const std::uint64_t id = ++self->accepted_;
    spdlog::debug("{}: client {} connected", self->endpoint_.text, id);
    self->clients_.emplace_back(id, StreamPeer::start(std::move(socket), self->max_queued_bytes_, self->on_read_));
    self->accept();
  });
}

void StreamServer::send(const StreamPeer::Message& message) {
  prune();
  for (const auto& [id, peer] : clients_) peer->send(message);
}

void StreamServer::prune() {
  std::erase_if(clients_, [this](const auto& client) {
    if (client.second->is_open()) return false;
    departed_ += client.second->counters();
    return true;
  });
}

void StreamServer::close() {
  if (!open_) return;
  open_ = false;
  error_code ignored;
  acceptor_.close(ignored);
  retry_.cancel();
  for (const auto& [id, peer] : clients_) peer->close();
  prune();
  std::error_code not_there;
  if (endpoint_.kind == Endpoint::Kind::unix_listen) std::filesystem::remove(endpoint_.path, not_there);
}

std::vector<std::pair<std::uint64_t, StreamPeer::Counters>> StreamServer::clients() const {
  std::vector<std::pair<std::uint64_t, StreamPeer::Counters>> out;
  for (const auto& [id, peer] : clients_) {
    if (peer->is_open()) out.emplace_back(id, peer->counters());
  }
  return out;
}

StreamPeer::Counters StreamServer::totals() const {
  StreamPeer::Counters sum = departed_;
  for (const auto& [id, peer] : clients_) sum += peer->counters();
  return sum;
}

// --- UDP ---

asio::ip::udp::endpoint udp_address(const Endpoint& endpoint) {
  return {asio::ip::make_address(endpoint.host), endpoint.port};
}

asio::ip::udp::socket open_udp(asio::io_context& io, const Endpoint& target) {
  const auto to = udp_address(target).address();
  asio::ip::address local;
  if (to.is_v4()) {
    local = to.is_loopback() ? asio::ip::address(asio::ip::address_v4::loopback()) : asio::ip::address_v4::any();
  } else {
    local = to.is_loopback() ? asio::ip::address(asio::ip::address_v6::loopback()) : asio::ip::address_v6::any();
  }
  asio::ip::udp::socket socket(io);
  error_code ec;
  socket.open(to.is_v4() ? asio::ip::udp::v4() : asio::ip::udp::v6(), ec);
  if (!ec) socket.bind({local, 0}, ec);
  if (!ec) socket.non_blocking(true, ec);
  if (ec) throw std::runtime_error(target.text + ": cannot open a UDP socket: " + ec.message());
  return socket;
}

}  // namespace imubridge::daemon
