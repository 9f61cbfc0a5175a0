// `imubridge run` serving [outputs.foxglove], checked with Foxglove's own client library (@foxglove/ws-protocol from
// npm, run by node on tests/foxglove_client.cjs): the channels advertised, every sample, estimate and event equal to
// what the store holds, and a client that stops reading losing its own messages, every one counted and stored as
// events, while another client and the recording lose nothing.
// clang-format off: <utility> first, for Boost 1.74 (daemon/asio.hpp)
#include "daemon/asio.hpp"
// clang-format on
#include <sys/socket.h>

#include <algorithm>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>
#include <cmath>
#include <fstream>
#include <iterator>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>
#include <thread>

#include "tests/support/cli_run_harness.hpp"
#include "tests/support/json_numbers.hpp"
#include "tests/support/loopback_port.hpp"
#include "tests/support/npm_packages.hpp"

namespace imubridge::test {
namespace {

using nlohmann::json;

// `node tests/foxglove_client.cjs URL` as a child process; what it prints (one JSON object per line) goes to a file,
// read here as it grows.
class NodeClient {
 public:
  NodeClient(const std::string& url, const fs::path& out) : out_(out) {
    pid_ = ::fork();
    if (pid_ != 0) return;
    if (!std::freopen(out.c_str(), "w", stdout) || !std::freopen((out.string() + ".err").c_str(), "w", stderr)) {
      ::_exit(127);
    }
    ::setenv("NODE_PATH", npm_node_path().c_str(), 1);
    const std::string script = std::string(IMUBRIDGE_SOURCE_DIR) + "/tests/foxglove_client.cjs";
    ::execlp("node", "node", script.c_str(), url.c_str(), nullptr);
    ::_exit(127);
  }
  ~NodeClient() {
    ::kill(pid_, SIGKILL);
    ::waitpid(pid_, nullptr, 0);
  }
  NodeClient(const NodeClient&) = delete;
  NodeClient& operator=(const NodeClient&) = delete;

  // The lines of `op` ("serverInfo", "advertise", "status").
  std::vector<json> lines(const std::string& op) {
    read();
    std::vector<json> out;
    for (const json& line : others_) {
      if (line.at("op") == op) out.push_back(line);
    }
    return out;
  }
  // The payloads of `topic`, parsed, in arrival order, each with its receive timestamp as "receiveTime".
  const std::vector<json>& on(const std::string& topic) {
    read();
    return messages_[topic];
  }
  std::string errors() const { return slurp(out_.string() + ".err"); }

 private:
  // The lines written since the last call; a line not yet ended waits for the next.
  void read() {
    std::ifstream in(out_, std::ios::binary);
    in.seekg(static_cast<std::streamoff>(read_bytes_));
    for (std::string line; std::getline(in, line) && !in.eof();) {
      read_bytes_ += line.size() + 1;
      json j = json::parse(line);
      if (j.at("op") != "message") {
        others_.push_back(std::move(j));
        continue;
      }
      json data = json::parse(j.at("data").get<std::string>());
      data["receiveTime"] = std::stoll(j.at("receiveTime").get<std::string>());
      messages_[j.at("topic").get<std::string>()].push_back(std::move(data));
    }
  }

  fs::path out_;
  pid_t pid_ = -1;
  std::size_t read_bytes_ = 0;
  std::vector<json> others_;
  std::map<std::string, std::vector<json>> messages_;
};

// The one advertisement a client gets: the channels of `links`, three each, JSON with a JSON schema, ids unique.
void expect_advertised(NodeClient& client, const std::vector<std::string>& links) {
  const auto info = client.lines("serverInfo");
  ASSERT_EQ(info.size(), 1u) << client.errors();
  EXPECT_EQ(info[0].at("info").at("name"), "imubridge " IMUBRIDGE_VERSION);
  const auto advertised = client.lines("advertise");
  ASSERT_EQ(advertised.size(), 1u);
  std::vector<std::string> topics, want;
  std::set<std::int64_t> ids;
  for (const json& channel : advertised[0].at("channels")) {
    topics.push_back(channel.at("topic"));
    ids.insert(channel.at("id").get<std::int64_t>());
    EXPECT_EQ(channel.at("encoding"), "json");
    EXPECT_EQ(channel.at("schemaEncoding"), "jsonschema");
    EXPECT_TRUE(json::parse(channel.at("schema").get<std::string>()).at("properties").is_object());
  }
  for (const std::string& link : links) {
    for (const char* channel : {"/sample", "/estimate", "/event"}) want.push_back(link + channel);
  }
  EXPECT_EQ(topics, want);
  EXPECT_EQ(ids.size(), topics.size());
}

// A link's sample messages: every stored sample, in order, as stored, stamped with its chunk's arrival.
void expect_samples_as_stored(const std::vector<json>& samples, const std::vector<protocol::Sample>& stored,
                              const std::string& link) {
  ASSERT_EQ(samples.size(), stored.size());
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const json& m = samples[i];
    const protocol::Sample& s = stored[i];
    ASSERT_EQ(m.at("seq").get<std::uint64_t>(), s.seq);
    EXPECT_EQ(m.at("link"), link);
    EXPECT_EQ(m.at("timestamp").get<double>(), static_cast<double>(s.device_time_us) / 1e6);
    for (std::size_t axis = 0; axis < 3; ++axis) {
      const char* name = std::array{"x", "y", "z"}[axis];
      EXPECT_TRUE(json_holds(m.at("accel").at(name), s.accel[axis])) << m;
      EXPECT_TRUE(json_holds(m.at("gyro").at(name), s.gyro[axis])) << m;
      if (s.has_mag) {
        EXPECT_TRUE(json_holds(m.at("mag").at(name), s.mag[axis])) << m;
      }
    }
    EXPECT_EQ(m.contains("mag"), s.has_mag);
    EXPECT_EQ(m.contains("temperature"), s.has_temperature);
    if (s.has_temperature) {
      EXPECT_TRUE(json_holds(m.at("temperature"), s.temperature_c)) << m;
    }
    EXPECT_EQ(m.at("receiveTime").get<std::int64_t>(), m.at("recv_wall_ns").get<std::int64_t>());
  }
}

// A link's estimate messages: every one the live run stored for the link, in order.
void expect_estimates_as_stored(const std::vector<json>& messages, const std::vector<store::Estimate>& estimates) {
  ASSERT_EQ(messages.size(), estimates.size());
  for (std::size_t i = 0; i < messages.size(); ++i) {
    const json& e = messages[i].at("estimate");
    ASSERT_EQ(e.at("seq").get<std::uint64_t>(), estimates[i].seq);
    EXPECT_TRUE(json_holds(e.at("fx"), estimates[i].fx)) << e;
    EXPECT_TRUE(json_holds(e.at("fy"), estimates[i].fy)) << e;
    EXPECT_TRUE(json_holds(e.at("vx"), estimates[i].vx)) << e;
    EXPECT_TRUE(json_holds(e.at("vy"), estimates[i].vy)) << e;
    EXPECT_TRUE(json_holds(e.at("sx"), std::sqrt(estimates[i].var_vx))) << e;
    EXPECT_TRUE(json_holds(e.at("sy"), std::sqrt(estimates[i].var_vy))) << e;
    EXPECT_EQ(messages[i].at("receiveTime").get<std::int64_t>(), messages[i].at("recv_wall_ns").get<std::int64_t>());
  }
}

// A link's event messages: the sequence gaps the recorder stored for the link, each as counted there.
void expect_gap_events_as_stored(const std::vector<json>& events, const std::vector<store::Event>& gaps,
                                 const std::string& link) {
  ASSERT_EQ(events.size(), gaps.size());
  for (std::size_t i = 0; i < events.size(); ++i) {
    EXPECT_EQ(events[i].at("kind"), "sequence_gap");
    EXPECT_EQ(events[i].at("link"), link);
    EXPECT_EQ(events[i].at("count").get<std::int64_t>(), gaps[i].count);
  }
}

// A client that subscribes to the first link's three channels (ids 1-3) and then reads nothing until
// start_reading(): Boost.Beast, with a 4 KiB receive buffer. Once reading, it keeps the seq of every sample and
// estimate it gets, in arrival order.
class StalledClient {
 public:
  explicit StalledClient(std::uint16_t port) {
    stream_.next_layer().open(boost::asio::ip::tcp::v4());
    stream_.next_layer().set_option(boost::asio::socket_base::receive_buffer_size(4096));
    stream_.next_layer().connect({boost::asio::ip::make_address("127.0.0.1"), port});
    stream_.set_option(
        boost::beast::websocket::stream_base::decorator([](boost::beast::websocket::request_type& request) {
          request.set(boost::beast::http::field::sec_websocket_protocol, "foxglove.websocket.v1");
        }));
    stream_.handshake("127.0.0.1", "/");
    stream_.text(true);
    stream_.write(boost::asio::buffer(std::string(
        R"({"op":"subscribe","subscriptions":[{"id":7,"channelId":1},{"id":8,"channelId":2},{"id":9,"channelId":3}]})")));
  }
  ~StalledClient() { stop(); }
  StalledClient(const StalledClient&) = delete;
  StalledClient& operator=(const StalledClient&) = delete;

  void start_reading() {
    reader_ = std::thread([this] {
      boost::beast::flat_buffer buffer;
      boost::system::error_code ec;
      while (stream_.read(buffer, ec), !ec) {
        const std::string frame = boost::beast::buffers_to_string(buffer.data());
        buffer.consume(buffer.size());
        if (stream_.got_binary()) take(frame);
      }
    });
  }
  // Closes the socket, should the server not have, and waits for the reader.
  void stop() {
    ::shutdown(stream_.next_layer().native_handle(), SHUT_RDWR);
    if (reader_.joinable()) reader_.join();
  }
  std::size_t received() {
    std::lock_guard lock(mutex_);
    return samples_.size() + estimates_.size();
  }
  // After stop().
  const std::vector<std::uint64_t>& samples() const { return samples_; }
  const std::vector<std::uint64_t>& estimates() const { return estimates_; }

 private:
  enum Subscription : std::uint32_t { kSample = 7, kEstimate = 8 };
  // Message data: opcode 0x01, subscription id (4 bytes, little-endian), time (8), payload.
  void take(const std::string& frame) {
    if (frame.size() < 13 || frame[0] != 0x01) return;
    std::uint32_t subscription = 0;
    for (int i = 0; i < 4; ++i) subscription |= std::uint32_t{static_cast<std::uint8_t>(frame[1 + i])} << (8 * i);
    const json payload = json::parse(frame.substr(13));
    std::lock_guard lock(mutex_);
    if (subscription == kSample) samples_.push_back(payload.at("seq"));
    if (subscription == kEstimate) estimates_.push_back(payload.at("estimate").at("seq"));
  }

  boost::asio::io_context io_;
  boost::beast::websocket::stream<boost::asio::ip::tcp::socket> stream_{io_};
  std::thread reader_;
  std::mutex mutex_;
  std::vector<std::uint64_t> samples_, estimates_;
};

class FoxgloveTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { install_error_ = install_npm_packages(); }
  void SetUp() override { ASSERT_EQ(install_error_, "") << install_error_; }

  // Links named `links`, each on a pty at dir/NAME, recorded into dir/run.db, served on a free loopback port.
  void start(const std::vector<std::string>& links, const std::string& foxglove_keys = "") {
    std::ofstream config(config_);
    config << "stats_interval_s = 3600\n[store]\npath = \"" << db_.string() << "\"\nmin_free_mib = 0\n"
           << "[outputs.foxglove]\nlisten = \"127.0.0.1:" << port_ << "\"\n"
           << foxglove_keys;
    for (const std::string& link : links) {
      config << "[[link]]\nname = \"" << link << "\"\ndevice = \"" << (dir_ / link).string()
             << "\"\nprotocol = \"imubridge\"\n";
    }
    config.close();
    daemon_ = std::make_unique<Process>(std::vector<std::string>{"run", "--config", config_.string()}, dir_ / "stderr");
    for (const std::string& link : links) {
      ASSERT_TRUE(daemon_->wait_for_log("link '" + link + "': reading")) << daemon_->log();
    }
    ASSERT_TRUE(daemon_->wait_for_log("foxglove: serving ws://127.0.0.1:" + std::to_string(port_))) << daemon_->log();
  }
  // Waits until the clients have made `subscriptions` subscriptions between them.
  void wait_for_subscriptions(int subscriptions) {
    ASSERT_TRUE(eventually([&] { return count_of(daemon_->log(), "subscribed to") >= subscriptions; }))
        << daemon_->log();
  }
  std::string url() const { return "ws://127.0.0.1:" + std::to_string(port_); }

  // outputs.foxglove of a stats line asked for now (SIGUSR1).
  json foxglove_counters() {
    const int lines = count_of(daemon_->log(), "stats {");
    daemon_->signal(SIGUSR1);
    EXPECT_TRUE(eventually([&] { return count_of(daemon_->log(), "stats {") > lines; })) << daemon_->log();
    const std::string log = daemon_->log();
    const auto at = log.rfind("stats {");
    return json::parse(log.substr(at + 6, log.find('\n', at) - at - 6)).at("outputs").at("foxglove");
  }
  // The foxglove_dropped events stored so far: the sum of their counts.
  std::int64_t stored_drops() const {
    const store::Store store(db_, {.read_only = true});
    const auto totals = event_totals(store, store.sessions().at(0).id);
    return totals.contains("foxglove_dropped") ? totals.at("foxglove_dropped") : 0;
  }

  // The estimates of the session's run stored so far.
  std::vector<store::Estimate> stored_estimates() const {
    std::vector<store::Estimate> estimates;
    const store::Store store(db_, {.read_only = true});
    store.for_each_estimate(store.runs(store.sessions().at(0).id).at(0).id,
                            [&](const store::Estimate& e) { estimates.push_back(e); });
    return estimates;
  }
  // `frames` written in batches, each once `client` has had the last on `link`: however slow this machine, that
  // client is never behind by more than a batch (some 40 KB with 50 frames) and that burst.
  void write_in_step_with(NodeClient& client, const std::string& link, cli::PtyPair& pty,
                          const std::vector<std::vector<std::uint8_t>>& frames, std::size_t batch) {
    for (std::size_t first = 0; first < frames.size(); first += batch) {
      const std::size_t last = std::min(first + batch, frames.size());
      write_paced(pty, {frames.begin() + static_cast<std::ptrdiff_t>(first),
                        frames.begin() + static_cast<std::ptrdiff_t>(last)});
      ASSERT_TRUE(eventually([&] { return client.on(link + "/sample").size() >= last; }))
          << client.on(link + "/sample").size() << " samples\n"
          << client.errors() << daemon_->log();
    }
  }

  static inline std::string install_error_;
  TempDir dir_;
  fs::path config_ = dir_ / "imubridge.toml", db_ = dir_ / "run.db";
  std::uint16_t port_ = free_loopback_port();
  std::unique_ptr<Process> daemon_;
};

TEST_F(FoxgloveTest, TheClientLibraryGetsEverySampleEstimateAndEventTheStoreHolds) {
  // Two links, so that each link's channels carry its own messages. On "imu" ten frames are lost on the way: the
  // recorder's sequence_gap event, and the server's on that link's event channel.
  auto imu_frames = simulated_frames(600);
  imu_frames.erase(imu_frames.begin() + 300, imu_frames.begin() + 310);
  const auto imu2_frames = simulated_frames(400, /*seed=*/5);
  cli::PtyPair imu(dir_ / "imu"), imu2(dir_ / "imu2");
  start({"imu", "imu2"});
  NodeClient client(url(), dir_ / "client.jsonl");
  wait_for_subscriptions(6);

  expect_advertised(client, {"imu", "imu2"});

  write_paced(imu, imu_frames);
  write_paced(imu2, imu2_frames);
  ASSERT_TRUE(wait_for_samples(db_, imu_frames.size() + imu2_frames.size())) << daemon_->log();
  // Every sample and estimate committed so far reached the client: the server has nothing more to send.
  ASSERT_TRUE(eventually([&] {
    return client.on("imu/sample").size() == imu_frames.size() &&
           client.on("imu2/sample").size() == imu2_frames.size() &&
           client.on("imu/estimate").size() + client.on("imu2/estimate").size() == stored_estimates().size();
  })) << client.errors()
      << client.on("imu/sample").size() << " " << client.on("imu2/sample").size();
  daemon_->signal(SIGTERM);
  ASSERT_EQ(daemon_->wait(), 0) << daemon_->log();

  const store::Store store(db_, {.read_only = true});
  const std::int64_t session = store.sessions().at(0).id;
  const auto all_estimates = stored_estimates();
  for (const store::Link& link : store.links(session)) {
    SCOPED_TRACE(link.name);
    std::vector<protocol::Sample> samples;
    store.for_each_sample(session, link.id, [&](const protocol::Sample& s) { samples.push_back(s); });
    expect_samples_as_stored(client.on(link.name + "/sample"), samples, link.name);
    std::vector<store::Estimate> estimates;
    std::copy_if(all_estimates.begin(), all_estimates.end(), std::back_inserter(estimates),
                 [&](const store::Estimate& e) { return e.link_id == link.id; });
    EXPECT_GE(estimates.size(), samples.size() / 2);
    expect_estimates_as_stored(client.on(link.name + "/estimate"), estimates);
    std::vector<store::Event> gaps;  // nothing dropped: the events are the recorder's gaps alone
    for (const store::Event& e : store.events(session)) {
      if (e.link_id == link.id && e.kind == "sequence_gap") gaps.push_back(e);
    }
    expect_gap_events_as_stored(client.on(link.name + "/event"), gaps, link.name);
  }
  EXPECT_EQ(client.on("imu/event").size(), 1u);
  ASSERT_FALSE(client.on("imu/event").empty());
  EXPECT_EQ(client.on("imu/event")[0].at("count"), 10);
  EXPECT_TRUE(client.on("imu2/event").empty());
  EXPECT_EQ(event_totals(store, session).count("foxglove_dropped"), 0u);
}

TEST_F(FoxgloveTest, AClientThatStopsReadingLosesItsOwnMessagesAndHoldsUpNoOne) {
  // About 4.5 MB of samples and estimates, against what a client that does not read can hold: its 512 KiB queue and
  // the sockets' buffers (the server's send buffer is 256 KiB, which Linux doubles; the client's receive buffer 4 KiB).
  // The queue is not smaller: when a link's IMU axes are found, the estimates held until then go at once, faster than
  // any client reads, and with 64 KiB part of them was dropped even for the reading client.
  constexpr std::size_t kFrames = 6000;
  const auto frames = simulated_frames(kFrames);
  cli::PtyPair pty(dir_ / "imu");
  start({"imu"}, "client_queue_kib = 512\n");

  StalledClient slow(port_);
  NodeClient client(url(), dir_ / "client.jsonl");
  wait_for_subscriptions(6);
  ASSERT_EQ(client.lines("advertise").size(), 1u);
  const json channels = client.lines("advertise")[0].at("channels");
  ASSERT_EQ(channels.size(), 3u);
  ASSERT_EQ(channels[0].at("id"), 1);  // the channels the slow client subscribed to by number
  ASSERT_EQ(channels[0].at("topic"), "imu/sample");
  ASSERT_EQ(channels[1].at("id"), 2);
  ASSERT_EQ(channels[2].at("id"), 3);

  // The reading client is never behind by more than a batch, well within its queue; the slow client is behind by
  // everything.
  write_in_step_with(client, "imu", pty, frames, 50);
  if (HasFatalFailure()) return;
  ASSERT_TRUE(wait_for_samples(db_, kFrames)) << daemon_->log();
  // The estimates that came with the last sample, then the server has sent all it will.
  ASSERT_TRUE(eventually([&] { return client.on("imu/estimate").size() == stored_estimates().size(); }))
      << client.on("imu/estimate").size() << " " << stored_estimates().size();
  const std::size_t sent = client.on("imu/sample").size() + client.on("imu/estimate").size();
  // Drops are reported every 5 s: logged, and stored as events of the link.
  ASSERT_TRUE(eventually([&] { return stored_drops() > 0; })) << daemon_->log();

  // The slow client reads again: it gets what its queue and the sockets held, in order, and misses the rest. What it
  // misses is what the server counted as dropped: the two add up to every sample and estimate sent.
  slow.start_reading();
  json foxglove;
  std::size_t received = 0;
  const bool adds_up = eventually([&] {
    received = slow.received();
    foxglove = foxglove_counters();
    return received + foxglove.at("client_dropped").get<std::size_t>() == sent;
  });
  // Every drop stored as an event, once reported.
  const bool stored = adds_up && eventually([&] {
                        foxglove = foxglove_counters();
                        return stored_drops() == foxglove.at("client_dropped").get<std::int64_t>();
                      });
  daemon_->signal(SIGTERM);
  const int exit_code = daemon_->wait();
  slow.stop();
  ASSERT_TRUE(adds_up) << received << " received by the slow client + " << foxglove << " != " << sent;
  ASSERT_TRUE(stored) << foxglove << " " << stored_drops();
  ASSERT_EQ(exit_code, 0) << daemon_->log();

  // The slow client lost most of it, in order, without a message twice.
  EXPECT_GT(foxglove.at("client_dropped").get<std::size_t>(), sent / 2) << foxglove;
  EXPECT_LT(slow.samples().size(), kFrames);
  EXPECT_TRUE(std::is_sorted(slow.samples().begin(), slow.samples().end()));
  EXPECT_EQ(std::adjacent_find(slow.samples().begin(), slow.samples().end()), slow.samples().end());
  EXPECT_TRUE(std::is_sorted(slow.estimates().begin(), slow.estimates().end()));
  // The reading client missed nothing, and neither did the recording.
  EXPECT_EQ(committed_samples(db_).size(), kFrames);
  const auto& samples = client.on("imu/sample");
  ASSERT_EQ(samples.size(), kFrames);
  for (std::size_t i = 0; i < samples.size(); ++i) ASSERT_EQ(samples[i].at("seq").get<std::uint64_t>(), i);
  EXPECT_GE(client.on("imu/event").size(), 1u) << "the drop reports go to every client";
  for (const json& event : client.on("imu/event")) EXPECT_EQ(event.at("kind"), "foxglove_dropped");
  EXPECT_EQ(foxglove.at("queue_dropped").get<std::int64_t>(), 0) << foxglove;
  EXPECT_EQ(foxglove.at("accepted").get<std::int64_t>(), 2) << foxglove;
  EXPECT_NE(daemon_->log().find("messages dropped for clients that read too slowly"), std::string::npos);
}

TEST_F(FoxgloveTest, AnAddressInUseIsOneLineAndExitCode1) {
  boost::asio::io_context io;
  boost::asio::ip::tcp::acceptor taken(io, {boost::asio::ip::make_address("127.0.0.1"), port_});
  std::ofstream(config_) << "[store]\npath = \"" << db_.string() << "\"\nmin_free_mib = 0\n[outputs.foxglove]\n"
                         << "listen = \"127.0.0.1:" << port_ << "\"\n[[link]]\nname = \"imu\"\ndevice = \""
                         << (dir_ / "tty").string() << "\"\n";
  const auto result = run_imubridge("run --config " + config_.string());
  EXPECT_EQ(result.exit_code, 1) << result.err;
  EXPECT_EQ(count_of(result.err, "\n"), 1) << result.err;
  EXPECT_NE(result.err.find("outputs.foxglove: cannot listen on 127.0.0.1:" + std::to_string(port_)), std::string::npos)
      << result.err;
}

}  // namespace
}  // namespace imubridge::test
