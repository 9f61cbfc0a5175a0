#pragma once
// The network endpoints of the configuration: parsing their text into daemon::Endpoint, and the sockets behind them
// that the outputs (daemon/outputs.hpp) and the link bridges (daemon/bridge.hpp) share. Everything here runs on one
// io_context thread. Objects with handlers in flight are owned by shared_ptr and their handlers hold a reference, so
// they live until their owner close()s them; once closed they do nothing more.
#include <sys/types.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "daemon/asio.hpp"
#include "daemon/config.hpp"

namespace imubridge::daemon {

// "udp://host:port", "tcp://host:port", "tcp-listen://host:port" or "unix:///absolute/path". The host is an IP
// address (IPv6 in brackets) or "localhost"; names are not resolved, so opening an endpoint never waits on DNS.
// Port 0 is allowed for tcp-listen only (the system picks a free port). Throws std::invalid_argument with one line
// naming the text and what is wrong with it.
Endpoint parse_endpoint(std::string_view text);

// The same socket address, however it was written ("localhost" and "127.0.0.1" are the same).
bool same_address(const Endpoint& a, const Endpoint& b);

using StreamSocket = boost::asio::generic::stream_protocol::socket;  // a TCP or unix stream socket

// One connected stream socket whose writes never block the caller: send() queues a message, and messages are written
// in the background. The queue is bounded in bytes; a message that does not fit is dropped whole (a JSON line or a
// chunk of link bytes is never cut) and counted. Bytes the other side sends go to on_read. When the connection fails
// (the other side closed it, a write failed) the peer closes itself and calls on_closed once; close() calls nothing.
class StreamPeer : public std::enable_shared_from_this<StreamPeer> {
 public:
  using Message = std::shared_ptr<const std::string>;  // shared by every peer it is sent to
  using OnRead = std::function<void(std::span<const std::uint8_t>)>;
  struct Counters {
    std::uint64_t messages_sent = 0, bytes_sent = 0;        // written to the socket
    std::uint64_t messages_dropped = 0, bytes_dropped = 0;  // did not fit the queue, or the peer was closed
    std::uint64_t messages_queued = 0, bytes_queued = 0;    // waiting to be written (in flight included)
    std::uint64_t bytes_received = 0;
    Counters& operator+=(const Counters& other);
  };

  static std::shared_ptr<StreamPeer> start(StreamSocket socket, std::size_t max_queued_bytes, OnRead on_read = {},
                                           std::function<void()> on_closed = {});
  void send(const Message& message);
  void close();
  bool is_open() const { return open_; }
  const Counters& counters() const { return counters_; }

 private:
  StreamPeer(StreamSocket socket, std::size_t max_queued_bytes, OnRead on_read, std::function<void()> on_closed);
  void read();
  void write();
  void fail();

  StreamSocket socket_;
  std::size_t max_queued_bytes_;
  OnRead on_read_;
  std::function<void()> on_closed_;
  bool open_ = true;
  std::vector<Message> pending_, writing_;  // writing_: the messages of the write in flight
  std::vector<boost::asio::const_buffer> buffers_;
  std::array<std::uint8_t, 4096> read_buffer_{};
  Counters counters_;
};

// Who may connect to a unix socket we listen on: the daemon's user and group (connecting needs write permission),
// whatever the umask. Under systemd the socket's directory (RuntimeDirectory) restricts it further.
inline constexpr mode_t kUnixSocketMode = 0660;

// Accepts clients on a tcp-listen or unix endpoint and sends each message to all of them (each through its own
// StreamPeer queue). A unix socket file left behind by a process that died is replaced; a socket some process still
// listens on, or any other file at the path, is an error. A unix socket file is created with kUnixSocketMode, and
// close() removes it again.
class StreamServer : public std::enable_shared_from_this<StreamServer> {
 public:
  // Throws std::runtime_error naming the endpoint when it cannot listen (address in use, no permission, ...).
  static std::shared_ptr<StreamServer> start(boost::asio::io_context& io, const Endpoint& endpoint,
                                             std::size_t max_queued_bytes, StreamPeer::OnRead on_read = {});
  void send(const StreamPeer::Message& message);
  void close();  // stops accepting and closes every client

  const Endpoint& endpoint() const { return endpoint_; }
  std::uint16_t port() const { return port_; }  // the bound TCP port (the system's choice for port 0); unix: 0
  std::uint64_t accepted() const { return accepted_; }
  // The clients connected now, oldest first, by number (1 = first accepted), and the counters summed over every
  // client since the start, departed ones included.
  std::vector<std::pair<std::uint64_t, StreamPeer::Counters>> clients() const;
  StreamPeer::Counters totals() const;

 private:
  StreamServer(boost::asio::io_context& io, const Endpoint& endpoint, std::size_t max_queued_bytes,
               StreamPeer::OnRead on_read);
  void accept();
  void prune();  // forgets closed clients, keeping their counters in departed_

  Endpoint endpoint_;
  boost::asio::basic_socket_acceptor<boost::asio::generic::stream_protocol> acceptor_;
  boost::asio::steady_timer retry_;  // pauses accepting after an error (out of file descriptors, say)
  std::size_t max_queued_bytes_;
  StreamPeer::OnRead on_read_;
  std::uint16_t port_ = 0;
  bool open_ = true;
  std::uint64_t accepted_ = 0;
  std::vector<std::pair<std::uint64_t, std::shared_ptr<StreamPeer>>> clients_;
  StreamPeer::Counters departed_;
};

// The socket address of a udp:// endpoint.
boost::asio::ip::udp::endpoint udp_address(const Endpoint& endpoint);

// A UDP socket for talking to `target`: bound to the loopback when the target is there, so nothing from outside can
// reach it, else to every interface; non-blocking, so a full send buffer drops a datagram instead of waiting.
boost::asio::ip::udp::socket open_udp(boost::asio::io_context& io, const Endpoint& target);

}  // namespace imubridge::daemon
