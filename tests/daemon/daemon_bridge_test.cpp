// Endpoint parsing, and the link bridge over real sockets on 127.0.0.1: UDP ground stations, tcp-listen clients, and
// a tcp:// station that is down at first.
#include <gtest/gtest.h>
#include <poll.h>

#include <chrono>
#include <stdexcept>
#include <string>
#include <vector>

#include "daemon/asio.hpp"
#include "daemon/bridge.hpp"

namespace imubridge::daemon {
namespace {

namespace asio = boost::asio;
using namespace std::chrono_literals;
using Bytes = std::vector<std::uint8_t>;

// Runs the io_context in short slices until `done` holds (or gives up after about five seconds); returns done().
template <class Done>
bool run_until(asio::io_context& io, Done done) {
  for (int i = 0; i < 500 && !done(); ++i) {
    io.restart();
    io.run_for(10ms);
  }
  return done();
}

Bytes every_byte_value() {
  Bytes bytes(256);
  for (int i = 0; i < 256; ++i) bytes[i] = static_cast<std::uint8_t>(i);
  return bytes;
}

// --- parse_endpoint ---

TEST(ParseEndpoint, AcceptsTheDocumentedForms) {
  const Endpoint udp = parse_endpoint("udp://127.0.0.1:14550");
  EXPECT_EQ(udp.kind, Endpoint::Kind::udp);
  EXPECT_EQ(udp.host, "127.0.0.1");
  EXPECT_EQ(udp.port, 14550);
  EXPECT_EQ(udp.text, "udp://127.0.0.1:14550");

  const Endpoint tcp = parse_endpoint("tcp://[::1]:5760");
  EXPECT_EQ(tcp.kind, Endpoint::Kind::tcp_connect);
  EXPECT_EQ(tcp.host, "::1");
  EXPECT_EQ(tcp.port, 5760);

  const Endpoint listen = parse_endpoint("tcp-listen://0.0.0.0:65535");
  EXPECT_EQ(listen.kind, Endpoint::Kind::tcp_listen);
  EXPECT_EQ(listen.host, "0.0.0.0");
  EXPECT_EQ(listen.port, 65535);
  EXPECT_EQ(parse_endpoint("tcp-listen://127.0.0.1:0").port, 0);  // the system picks a port

  const Endpoint unix = parse_endpoint("unix:///run/imubridge/lines.sock");
  EXPECT_EQ(unix.kind, Endpoint::Kind::unix_listen);
  EXPECT_EQ(unix.path, "/run/imubridge/lines.sock");

  EXPECT_EQ(parse_endpoint("udp://localhost:9870").host, "127.0.0.1");
  EXPECT_TRUE(same_address(parse_endpoint("udp://localhost:9870"), parse_endpoint("udp://127.0.0.1:9870")));
  EXPECT_FALSE(same_address(parse_endpoint("udp://127.0.0.1:9870"), parse_endpoint("tcp://127.0.0.1:9870")));
}

TEST(ParseEndpoint, RejectsWithOneLineNamingTheText) {
  for (const std::string& bad : std::vector<std::string>{
           "",
           "127.0.0.1:14550",                  // no scheme
           "http://127.0.0.1:80",              // unknown scheme
           "udp://127.0.0.1",                  // no port
           "udp://:14550",                     // no host
           "udp://127.0.0.1:",                 // empty port
           "udp://127.0.0.1:65536",            // port out of range
           "udp://127.0.0.1:14x",              // not a number
           "udp://127.0.0.1:-1",               // not a number either
           "udp://127.0.0.1:0",                // port 0 is for tcp-listen only
           "tcp://127.0.0.1:0",                //
           "udp://ground.local:14550",         // names are not resolved
           "udp://300.1.1.1:14550",            // not an address
           "tcp://::1:5760",                   // IPv6 without brackets
           "tcp://[127.0.0.1]:5760",           // brackets around IPv4
           "tcp://[::1:5760",                  // unclosed bracket
           "tcp://[::1]5760",                  // no colon before the port
           "unix://run/imubridge.sock",        // relative path
           "unix://",                          // no path
           "unix:///" + std::string(200, 'a')  // longer than sun_path
       }) {
    try {
      parse_endpoint(bad);
      ADD_FAILURE() << "accepted '" << bad << "'";
    } catch (const std::invalid_argument& e) {
      const std::string message = e.what();
      EXPECT_NE(message.find("'" + bad + "'"), std::string::npos) << message;
      EXPECT_EQ(message.find('\n'), std::string::npos) << message;
    }
  }
}

// --- LinkBridge ---

struct ToLink {
  Bytes bytes;
  std::function<void(std::span<const std::uint8_t>)> sink() {
    return [this](std::span<const std::uint8_t> b) { bytes.insert(bytes.end(), b.begin(), b.end()); };
  }
};

// A socket this test reads from without an io_context: waits at most two seconds for the next bytes.
template <class Socket>
Bytes receive_some(Socket& socket) {
  pollfd p{socket.native_handle(), POLLIN, 0};
  if (::poll(&p, 1, 2000) != 1) return {};
  Bytes bytes(65536);
  bytes.resize(socket.receive(asio::buffer(bytes)));
  return bytes;
}

TEST(LinkBridge, UdpStationGetsLinkBytesAndItsRepliesReachTheLink) {
  asio::io_context io;
  asio::ip::udp::socket station(io, {asio::ip::make_address("127.0.0.1"), 0});
  ToLink to_link;
  LinkBridge bridge(io, {parse_endpoint("udp://127.0.0.1:" + std::to_string(station.local_endpoint().port()))},
                    to_link.sink());

  const Bytes from_vehicle = every_byte_value();
  bridge.from_link(from_vehicle);
  asio::ip::udp::endpoint bridge_address;
  Bytes got(65536);
  pollfd p{station.native_handle(), POLLIN, 0};
  ASSERT_EQ(::poll(&p, 1, 2000), 1);
  got.resize(station.receive_from(asio::buffer(got), bridge_address));
  EXPECT_EQ(got, from_vehicle);

  // The station answers whoever sent to it, as QGroundControl does; a stranger's datagram is not for the link.
  asio::ip::udp::socket stranger(io, {asio::ip::make_address("127.0.0.1"), 0});
  stranger.send_to(asio::buffer(std::string("not from the station")), bridge_address);
  const Bytes command{0xFD, 0x09, 0x00, 0x7E, 0x7D, 0x00, 0xFF};
  station.send_to(asio::buffer(command), bridge_address);
  ASSERT_TRUE(run_until(io, [&] { return to_link.bytes.size() >= command.size(); }));
  EXPECT_EQ(to_link.bytes, command);

  const auto counters = bridge.counters()[0];
  EXPECT_EQ(counters["bytes_sent"], from_vehicle.size());
  EXPECT_EQ(counters["bytes_received"], command.size());
  EXPECT_EQ(counters["datagrams_ignored"], 1);
}

TEST(LinkBridge, TcpListenClientsGetLinkBytesAndTheirBytesReachTheLink) {
  asio::io_context io;
  ToLink to_link;
  LinkBridge bridge(io, {parse_endpoint("tcp-listen://127.0.0.1:0")}, to_link.sink());
  const auto port = bridge.counters()[0]["port"].get<std::uint16_t>();
  asio::ip::tcp::socket station(io);
  station.connect({asio::ip::make_address("127.0.0.1"), port});
  ASSERT_TRUE(run_until(io, [&] { return bridge.counters()[0]["clients"] == 1; }));

  Bytes from_vehicle;
  for (int i = 0; i < 40; ++i) {  // 40 chunks of every byte value: 10 KiB, read back in whatever pieces TCP makes
    const Bytes chunk = every_byte_value();
    bridge.from_link(chunk);
    from_vehicle.insert(from_vehicle.end(), chunk.begin(), chunk.end());
  }
  Bytes got;
  ASSERT_TRUE(run_until(io, [&] {
    if (station.available() > 0) {
      const Bytes piece = receive_some(station);
      got.insert(got.end(), piece.begin(), piece.end());
    }
    return got.size() >= from_vehicle.size();
  }));
  EXPECT_EQ(got, from_vehicle);

  const Bytes command = every_byte_value();
  asio::write(station, asio::buffer(command));
  ASSERT_TRUE(run_until(io, [&] { return to_link.bytes.size() >= command.size(); }));
  EXPECT_EQ(to_link.bytes, command);
}

TEST(LinkBridge, TcpStationThatIsDownIsRetriedUntilItComesUp) {
  asio::io_context io;
  // Find a free port, and leave it closed for now.
  std::uint16_t port = 0;
  {
    asio::ip::tcp::acceptor probe(io, {asio::ip::make_address("127.0.0.1"), 0});
    port = probe.local_endpoint().port();
  }
  ToLink to_link;
  LinkBridge bridge(io, {parse_endpoint("tcp://127.0.0.1:" + std::to_string(port))}, to_link.sink());
  ASSERT_TRUE(run_until(io, [&] { return bridge.counters()[0]["connect_failures"] >= 2; }));
  EXPECT_EQ(bridge.counters()[0]["connected"], false);

  asio::ip::tcp::acceptor station(io, {asio::ip::make_address("127.0.0.1"), port});
  asio::ip::tcp::socket accepted(io);
  station.async_accept(accepted, [](boost::system::error_code) {});
  ASSERT_TRUE(run_until(io, [&] { return bridge.counters()[0]["connected"] == true && accepted.is_open(); }));

  const Bytes from_vehicle = every_byte_value();
  bridge.from_link(from_vehicle);
  Bytes got(from_vehicle.size());
  bool read = false;
  asio::async_read(accepted, asio::buffer(got), [&](boost::system::error_code ec, std::size_t) { read = !ec; });
  ASSERT_TRUE(run_until(io, [&] { return read; }));
  EXPECT_EQ(got, from_vehicle);

  // The station hangs up: the bridge connects again.
  accepted.close();
  asio::ip::tcp::socket again(io);
  station.async_accept(again, [](boost::system::error_code) {});
  ASSERT_TRUE(run_until(io, [&] { return bridge.counters()[0]["connects"] == 2 && again.is_open(); }));
}

TEST(LinkBridge, RefusesAnEndpointItCannotOpen) {
  asio::io_context io;
  asio::ip::tcp::acceptor taken(io, {asio::ip::make_address("127.0.0.1"), 0});
  const std::string busy = "tcp-listen://127.0.0.1:" + std::to_string(taken.local_endpoint().port());
  try {
    LinkBridge bridge(io, {parse_endpoint(busy)}, [](std::span<const std::uint8_t>) {});
    ADD_FAILURE() << "listened on a port in use";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(busy), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace imubridge::daemon
