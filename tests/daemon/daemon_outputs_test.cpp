// Live outputs over real sockets on 127.0.0.1 and in a temporary directory: PlotJuggler datagrams, line streams over
// TCP and unix sockets, slow subscribers, decimation and reconfiguration.
#include <gtest/gtest.h>
#include <poll.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <utility>

#include "daemon/asio.hpp"
#include "daemon/outputs.hpp"
#include "tests/support/temp_dir.hpp"

namespace imubridge::daemon {
namespace {

namespace asio = boost::asio;
using namespace std::chrono_literals;
using nlohmann::json;

// Runs the io_context in short slices until `done` holds (or gives up after about five seconds); returns done().
template <class Done>
bool run_until(asio::io_context& io, Done done) {
  for (int i = 0; i < 500 && !done(); ++i) {
    io.restart();
    io.run_for(10ms);
  }
  return done();
}

class UdpReceiver {
 public:
  explicit UdpReceiver(asio::io_context& io) : socket_(io, {asio::ip::make_address("127.0.0.1"), 0}) {}
  std::string endpoint() const { return "udp://127.0.0.1:" + std::to_string(socket_.local_endpoint().port()); }

  // The next datagram, waiting at most `wait_ms` for it.
  std::optional<std::string> receive(int wait_ms = 2000) {
    pollfd p{socket_.native_handle(), POLLIN, 0};
    if (::poll(&p, 1, wait_ms) != 1) return std::nullopt;
    std::string datagram(65536, '\0');
    datagram.resize(socket_.receive(asio::buffer(datagram)));
    return datagram;
  }

 private:
  asio::ip::udp::socket socket_;
};

// A subscriber: connects at once, and collects lines while the io_context runs, if told to read.
class Subscriber {
 public:
  Subscriber(asio::io_context& io, const asio::generic::stream_protocol::endpoint& address,
             std::optional<int> receive_buffer = std::nullopt)
      : socket_(io) {
    socket_.open(address.protocol());
    if (receive_buffer) socket_.set_option(asio::socket_base::receive_buffer_size(*receive_buffer));
    socket_.connect(address);
  }
  static Subscriber tcp(asio::io_context& io, std::uint16_t port, std::optional<int> receive_buffer = std::nullopt) {
    return Subscriber(io, asio::ip::tcp::endpoint(asio::ip::make_address("127.0.0.1"), port), receive_buffer);
  }
  static Subscriber unix(asio::io_context& io, const std::filesystem::path& path) {
    return Subscriber(io, asio::local::stream_protocol::endpoint(path));
  }

  void read() {
    asio::async_read_until(socket_, buffer_, '\n', [this](boost::system::error_code ec, std::size_t n) {
      if (ec) {
        closed = true;
        return;
      }
      const auto begin = asio::buffers_begin(buffer_.data());
      lines.emplace_back(begin, begin + static_cast<std::ptrdiff_t>(n - 1));
      buffer_.consume(n);
      read();
    });
  }

  std::vector<std::string> lines;
  bool closed = false;

 private:
  asio::generic::stream_protocol::socket socket_;
  asio::streambuf buffer_;
};

using test::TempDir;

protocol::Sample sample(std::uint64_t seq) {
  return {.seq = seq, .device_time_us = 1'500'000 + 10'000 * static_cast<std::int64_t>(seq)};
}

// (Built by hand: OutputsConfig's members have no default initializers, so designated ones would warn.)
OutputsConfig outputs_config(std::optional<std::string> plotjuggler, const std::vector<std::string>& line_streams = {},
                             std::uint32_t decimation = 1) {
  OutputsConfig config;
  if (plotjuggler) config.plotjuggler = parse_endpoint(*plotjuggler);
  for (const auto& text : line_streams) config.line_streams.push_back(parse_endpoint(text));
  config.decimation = decimation;
  return config;
}

std::uint16_t line_stream_port(const Outputs& outputs, std::size_t i) {
  return outputs.counters()["line_streams"][i]["port"].get<std::uint16_t>();
}

std::size_t subscribers(const Outputs& outputs, std::size_t i) {
  return outputs.counters()["line_streams"][i]["subscribers"].size();
}

TEST(Outputs, PlotJugglerGetsOneDatagramPerSampleWithTheLinkAsAPathLevel) {
  asio::io_context io;
  UdpReceiver plotjuggler(io);
  Outputs outputs(io, outputs_config(plotjuggler.endpoint()));

  const protocol::Sample s{
      .seq = 42, .device_time_us = 1'500'000, .accel = {0.5, -0.25, -9.75}, .gyro = {0.125, 0, -1}};
  const store::Estimate e{.seq = 40, .fx = 0.25, .fy = -0.5, .vx = 1.5, .vy = -2, .var_vx = 0.25, .var_vy = 0.0625};
  outputs.publish("radio1", s, &e);
  EXPECT_EQ(json::parse(plotjuggler.receive().value()), json::parse(R"({"timestamp": 1.5, "radio1": {
      "seq": 42, "accel": {"x": 0.5, "y": -0.25, "z": -9.75}, "gyro": {"x": 0.125, "y": 0, "z": -1},
      "estimate": {"seq": 40, "fx": 0.25, "fy": -0.5, "vx": 1.5, "vy": -2, "sx": 0.5, "sy": 0.25}}})"));

  // No estimate: no "estimate"; magnetometer and temperature when the sample has them; NaN as null.
  const protocol::Sample t{.seq = 43,
                           .device_time_us = 1'510'000,
                           .accel = {std::numeric_limits<double>::quiet_NaN(), 0, -9.75},
                           .mag = {20, -5, 40},
                           .temperature_c = 25.5,
                           .has_mag = true,
                           .has_temperature = true};
  outputs.publish("radio2", t, nullptr);
  EXPECT_EQ(json::parse(plotjuggler.receive().value()), json::parse(R"({"timestamp": 1.51, "radio2": {
      "seq": 43, "accel": {"x": null, "y": 0, "z": -9.75}, "gyro": {"x": 0, "y": 0, "z": 0},
      "mag": {"x": 20, "y": -5, "z": 40}, "temperature": 25.5}})"));
  EXPECT_EQ(outputs.counters()["plotjuggler"]["datagrams_sent"], 2);
}

// The messages are written by hand (outputs.cpp): every double must read back to the same bits, and a link name with
// any bytes must still make valid JSON (quotes and control characters escaped, bytes beyond ASCII as U+FFFD).
TEST(Outputs, NumbersReadBackExactlyAndAnyLinkNameMakesValidJson) {
  asio::io_context io;
  UdpReceiver plotjuggler(io);
  Outputs outputs(io, outputs_config(plotjuggler.endpoint()));
  const std::array<double, 3> accel{1.0 / 3.0, -0.0, std::numeric_limits<double>::denorm_min()};
  const std::array<double, 3> gyro{1e300, -123456789.125, 0.1 + 0.2};
  const protocol::Sample s{.seq = std::numeric_limits<std::uint64_t>::max(), .accel = accel, .gyro = gyro};
  const std::string link = std::string("a\"b\\c\n") + '\x01' + "\xff/x";
  outputs.publish(link, s, nullptr);

  const json j = json::parse(plotjuggler.receive().value());  // throws, failing the test, if not valid JSON
  ASSERT_EQ(j.size(), 2u);
  const json& body = j.at("a\"b\\c\n\u0001\ufffd/x");
  EXPECT_EQ(body.at("seq").get<std::uint64_t>(), s.seq);
  for (std::size_t i = 0; i < 3; ++i) {
    const char* axis[] = {"x", "y", "z"};
    EXPECT_EQ(std::bit_cast<std::uint64_t>(body["accel"][axis[i]].get<double>()),
              std::bit_cast<std::uint64_t>(accel[i]))
        << "accel." << axis[i];
    EXPECT_EQ(std::bit_cast<std::uint64_t>(body["gyro"][axis[i]].get<double>()), std::bit_cast<std::uint64_t>(gyro[i]))
        << "gyro." << axis[i];
  }
}

// Connecting to a unix socket takes write permission: 0660 lets the daemon's user and group in, and nobody else,
// whatever umask the daemon was started with.
TEST(Outputs, AUnixSocketIsForTheDaemonsUserAndGroupWhateverTheUmask) {
  TempDir dir;
  for (const mode_t umask : {mode_t{0}, mode_t{022}, mode_t{077}}) {
    asio::io_context io;
    const auto socket_path = dir.path() / "lines.sock";
    const mode_t previous = ::umask(umask);
    auto outputs = std::make_unique<Outputs>(io, outputs_config({}, {"unix://" + socket_path.string()}));
    ::umask(previous);
    EXPECT_EQ(std::filesystem::status(socket_path).permissions(),
              std::filesystem::perms::owner_read | std::filesystem::perms::owner_write |
                  std::filesystem::perms::group_read | std::filesystem::perms::group_write)
        << "umask " << std::oct << umask;
    outputs.reset();
    EXPECT_FALSE(std::filesystem::exists(socket_path));
  }
}

TEST(Outputs, LineStreamsOverTcpAndUnixSocketsDeliverEveryLine) {
  asio::io_context io;
  TempDir dir;
  const auto socket_path = dir.path() / "lines.sock";
  Outputs outputs(io, outputs_config({}, {"tcp-listen://127.0.0.1:0", "unix://" + socket_path.string()}));
  Subscriber over_tcp = Subscriber::tcp(io, line_stream_port(outputs, 0));
  Subscriber over_unix = Subscriber::unix(io, socket_path);
  over_tcp.read();
  over_unix.read();
  ASSERT_TRUE(run_until(io, [&] { return subscribers(outputs, 0) == 1 && subscribers(outputs, 1) == 1; }));

  const store::Estimate e{.seq = 1, .fx = 0.5, .fy = 0, .vx = 0.25, .vy = 0, .var_vx = 1, .var_vy = -1};
  for (std::uint64_t seq = 0; seq < 3; ++seq) outputs.publish("imu0", sample(seq), seq == 2 ? &e : nullptr);
  ASSERT_TRUE(run_until(io, [&] { return over_tcp.lines.size() == 3 && over_unix.lines.size() == 3; }));

  EXPECT_EQ(over_tcp.lines, over_unix.lines);
  for (std::uint64_t seq = 0; seq < 3; ++seq) EXPECT_EQ(json::parse(over_tcp.lines[seq])["seq"], seq);
  // A negative variance has no standard deviation: null.
  EXPECT_EQ(json::parse(over_tcp.lines[2]), json::parse(R"({"timestamp": 1.52, "link": "imu0", "seq": 2,
      "accel": {"x": 0, "y": 0, "z": 0}, "gyro": {"x": 0, "y": 0, "z": 0},
      "estimate": {"seq": 1, "fx": 0.5, "fy": 0, "vx": 0.25, "vy": 0, "sx": 1, "sy": null}})"));
}

TEST(Outputs, SlowSubscriberLosesLinesWhileAnotherGetsEverything) {
  asio::io_context io;
  Outputs outputs(io, outputs_config({}, {"tcp-listen://127.0.0.1:0"}));
  const std::uint16_t port = line_stream_port(outputs, 0);
  Subscriber fast = Subscriber::tcp(io, port);
  fast.read();
  ASSERT_TRUE(run_until(io, [&] { return subscribers(outputs, 0) == 1; }));
  Subscriber slow = Subscriber::tcp(io, port, 4096);  // connected, but never reads
  ASSERT_TRUE(run_until(io, [&] { return subscribers(outputs, 0) == 2; }));

  // publish() returning at all while `slow` reads nothing is the "never blocks" part. Publish until its queue
  // overflows, then some more, letting the io_context write between publishes as the daemon's loop would.
  const auto slow_counters = [&] { return outputs.counters()["line_streams"][0]["subscribers"][1]; };
  std::uint64_t published = 0;
  while (published < 200'000 && (published % 100 != 0 || slow_counters()["lines_dropped"] == 0)) {
    outputs.publish("imu0", sample(published++), nullptr);
    io.poll();
  }
  for (int i = 0; i < 100; ++i) {
    outputs.publish("imu0", sample(published++), nullptr);
    io.poll();
  }
  ASSERT_TRUE(run_until(io, [&] { return fast.lines.size() == published; }));

  const json slow_now = slow_counters();
  EXPECT_EQ(slow_now["id"], 2);
  EXPECT_GT(slow_now["lines_dropped"], 0);
  EXPECT_EQ(slow_now["lines_sent"].get<std::uint64_t>() + slow_now["lines_dropped"].get<std::uint64_t>() +
                slow_now["lines_queued"].get<std::uint64_t>(),
            published);
  const json fast_now = outputs.counters()["line_streams"][0]["subscribers"][0];
  EXPECT_EQ(fast_now["lines_dropped"], 0);
  EXPECT_EQ(fast_now["lines_sent"], published);
  for (std::uint64_t i = 0; i < published; i += 997) EXPECT_EQ(json::parse(fast.lines[i])["seq"], i);
}

TEST(Outputs, ReconfigureMovesPlotJugglerAndKeepsUnchangedStreams) {
  asio::io_context io;
  TempDir dir;
  const auto socket_path = dir.path() / "lines.sock";
  UdpReceiver first(io), second(io);
  const std::string tcp_stream = "tcp-listen://127.0.0.1:0";
  Outputs outputs(io, outputs_config(first.endpoint(), {tcp_stream, "unix://" + socket_path.string()}));
  Subscriber kept = Subscriber::tcp(io, line_stream_port(outputs, 0));
  Subscriber removed = Subscriber::unix(io, socket_path);
  kept.read();
  removed.read();
  ASSERT_TRUE(run_until(io, [&] { return subscribers(outputs, 0) == 1 && subscribers(outputs, 1) == 1; }));
  outputs.publish("imu0", sample(0), nullptr);
  EXPECT_TRUE(first.receive());

  // The same tcp-listen endpoint (port 0 included) is kept with its subscriber; the unix one goes away.
  outputs.reconfigure(outputs_config(second.endpoint(), {tcp_stream}));
  outputs.publish("imu0", sample(1), nullptr);
  EXPECT_EQ(json::parse(second.receive().value())["imu0"]["seq"], 1);
  EXPECT_FALSE(first.receive(100));
  ASSERT_TRUE(run_until(io, [&] { return kept.lines.size() == 2 && removed.closed; }));
  EXPECT_EQ(outputs.counters()["line_streams"][0]["accepted"], 1);
  EXPECT_EQ(removed.lines.size(), 1u);
  EXPECT_FALSE(std::filesystem::exists(socket_path));
}

TEST(Outputs, FailedReconfigureChangesNothing) {
  asio::io_context io;
  UdpReceiver first(io), second(io);
  Outputs outputs(io, outputs_config(first.endpoint()));
  asio::ip::tcp::acceptor taken(io, {asio::ip::make_address("127.0.0.1"), 0});  // a port someone else listens on
  const std::string busy = "tcp-listen://127.0.0.1:" + std::to_string(taken.local_endpoint().port());

  EXPECT_THROW(outputs.reconfigure(outputs_config(second.endpoint(), {"tcp-listen://127.0.0.1:0", busy})),
               std::runtime_error);
  outputs.publish("imu0", sample(0), nullptr);
  EXPECT_TRUE(first.receive());
  EXPECT_FALSE(second.receive(100));
  EXPECT_TRUE(outputs.counters()["line_streams"].empty());
}

TEST(Outputs, DecimationKeepsEveryNthSampleOfEachLink) {
  asio::io_context io;
  UdpReceiver plotjuggler(io);
  Outputs outputs(io, outputs_config(plotjuggler.endpoint(), {}, 3));
  for (std::uint64_t seq = 0; seq < 7; ++seq) {
    outputs.publish("a", sample(seq), nullptr);
    outputs.publish("b", sample(seq), nullptr);
  }
  std::vector<std::pair<std::string, std::uint64_t>> got;
  while (const auto datagram = plotjuggler.receive(100)) {
    const json j = json::parse(*datagram);
    for (const auto& [key, value] : j.items()) {
      if (key != "timestamp") got.emplace_back(key, value["seq"].get<std::uint64_t>());
    }
  }
  const std::vector<std::pair<std::string, std::uint64_t>> want{{"a", 0}, {"b", 0}, {"a", 3},
                                                                {"b", 3}, {"a", 6}, {"b", 6}};
  EXPECT_EQ(got, want);
  EXPECT_EQ(outputs.counters()["samples_published"], 6);
}

TEST(Outputs, RefusesEndpointsOfTheWrongKind) {
  asio::io_context io;
  EXPECT_THROW(Outputs(io, outputs_config("tcp-listen://127.0.0.1:0")), std::invalid_argument);
  EXPECT_THROW(Outputs(io, outputs_config({}, {"udp://127.0.0.1:9870"})), std::invalid_argument);
  EXPECT_THROW(Outputs(io, outputs_config({}, {}, 0)), std::invalid_argument);
}

}  // namespace
}  // namespace imubridge::daemon
