// `imubridge run` publishing to a real Mosquitto broker that the test starts on a free loopback port: messages in
// order and in the line streams' JSON, a broker killed and restarted mid-run costing no recorded sample, the last
// will on kill -9, and one-line errors for a bad [outputs.mqtt].
#include <mosquitto.h>

#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>

#include "daemon/config_file.hpp"
#include "pipeline/estimation_stage.hpp"
#include "tests/support/cli_run_harness.hpp"
#include "tests/support/loopback_port.hpp"

namespace imubridge::test {
namespace {

using nlohmann::json;

bool accepts_connections(std::uint16_t port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{
      .sin_family = AF_INET, .sin_port = htons(port), .sin_addr = {htonl(INADDR_LOOPBACK)}, .sin_zero = {}};
  const bool ok = ::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0;
  ::close(fd);
  return ok;
}

// `mosquitto -c dir/mosquitto.conf`: anonymous, on 127.0.0.1:port only, nothing kept on disk (a restart forgets
// retained messages, as a broker without persistence does).
class Broker {
 public:
  // `listener_settings`: the listener's lines, such as its TLS files or who may connect.
  explicit Broker(const fs::path& dir, const std::string& listener_settings = "allow_anonymous true\n")
      : dir_(dir), port_(test::free_loopback_port()) {
    std::ofstream(dir_ / "mosquitto.conf") << "listener " << port_ << " 127.0.0.1\n"
                                           << listener_settings << "persistence false\nlog_dest stderr\n";
    start();
  }
  ~Broker() { stop(SIGKILL); }
  Broker(const Broker&) = delete;
  Broker& operator=(const Broker&) = delete;

  void start() {
    pid_ = ::fork();
    if (pid_ == 0) {
      // Opened before exec: run as root, mosquitto goes on as the user "mosquitto", who cannot open files in dir_.
      if (!std::freopen((dir_ / "mosquitto.log").c_str(), "a", stderr)) ::_exit(127);
      ::close_range(3, ~0u, 0);
      ::execl("/usr/sbin/mosquitto", "mosquitto", "-c", (dir_ / "mosquitto.conf").c_str(), nullptr);
      ::_exit(127);
    }
    ASSERT_TRUE(eventually([&] { return accepts_connections(port_); })) << slurp(dir_ / "mosquitto.log");
  }
  void stop(int signal) {
    if (pid_ <= 0) return;
    ::kill(pid_, signal);
    ::waitpid(pid_, nullptr, 0);
    pid_ = -1;
  }
  std::uint16_t port() const { return port_; }
  std::string url() const { return "mqtt://127.0.0.1:" + std::to_string(port_); }

 private:
  fs::path dir_;
  std::uint16_t port_;
  pid_t pid_ = -1;
};

struct Received {
  std::string topic;
  std::string payload;
  bool retained;
};

// A subscriber to imubridge/# with libmosquitto, as a dashboard would be; keeps every message in arrival order.
class Subscriber {
 public:
  // `ca_file`: connect with TLS, trusting these CAs.
  explicit Subscriber(std::uint16_t port, const std::optional<fs::path>& ca_file = std::nullopt) {
    mosquitto_lib_init();
    client_ = mosquitto_new(nullptr, true, this);
    if (ca_file) mosquitto_tls_set(client_, ca_file->c_str(), nullptr, nullptr, nullptr, nullptr);
    mosquitto_message_callback_set(client_, [](mosquitto*, void* self, const mosquitto_message* m) {
      auto& s = *static_cast<Subscriber*>(self);
      std::lock_guard lock(s.mutex_);
      s.messages_.push_back({m->topic, std::string(static_cast<const char*>(m->payload), m->payloadlen), m->retain});
    });
    mosquitto_subscribe_callback_set(client_, [](mosquitto*, void* self, int, int, const int*) {
      static_cast<Subscriber*>(self)->subscribed_ = true;
    });
    mosquitto_connect_callback_set(client_, [](mosquitto* client, void*, int rc) {
      if (rc == 0) mosquitto_subscribe(client, nullptr, "imubridge/#", 1);
    });
    EXPECT_EQ(mosquitto_connect(client_, "127.0.0.1", port, 60), MOSQ_ERR_SUCCESS);
    mosquitto_loop_start(client_);
    EXPECT_TRUE(eventually([&] { return subscribed_.load(); }));
  }
  ~Subscriber() {
    mosquitto_disconnect(client_);
    mosquitto_loop_stop(client_, false);
    mosquitto_destroy(client_);
  }
  Subscriber(const Subscriber&) = delete;
  Subscriber& operator=(const Subscriber&) = delete;

  std::vector<Received> messages() const {
    std::lock_guard lock(mutex_);
    return messages_;
  }
  // The payloads on `topic`, parsed, in arrival order.
  std::vector<json> on(const std::string& topic) const {
    std::vector<json> out;
    for (const auto& m : messages()) {
      if (m.topic == topic) out.push_back(json::parse(m.payload));
    }
    return out;
  }
  bool wait_for(const std::string& topic, std::size_t count, std::chrono::milliseconds limit = 20s) const {
    return eventually([&] { return on(topic).size() >= count; }, limit);
  }

 private:
  mosquitto* client_ = nullptr;
  std::atomic<bool> subscribed_{false};
  mutable std::mutex mutex_;
  std::vector<Received> messages_;
};

std::int64_t wall_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

class MqttTest : public ::testing::Test {
 protected:
  // One link "imu" on a pty at dir/tty, recorded into dir/run.db, publishing as station "field-1".
  void write_config(const std::string& mqtt_keys) {
    std::ofstream(config_) << "stats_interval_s = 3600\n[store]\npath = \"" << db_.string()
                           << "\"\nmin_free_mib = 0\n[outputs.mqtt]\nurl = \"" << broker_.url()
                           << "\"\nstation = \"field-1\"\n"
                           << mqtt_keys << "[[link]]\nname = \"imu\"\ndevice = \"" << tty_.string()
                           << "\"\nprotocol = \"imubridge\"\nreconnect_min_ms = 10\nreconnect_max_ms = 50\n";
  }
  void start() {
    daemon_ = std::make_unique<Process>(std::vector<std::string>{"run", "--config", config_.string()}, dir_ / "stderr");
    ASSERT_TRUE(daemon_->wait_for_log("link 'imu': reading")) << daemon_->log();
  }
  void stop() {
    daemon_->signal(SIGTERM);
    ASSERT_EQ(daemon_->wait(), 0) << daemon_->log();
  }

  TempDir dir_;
  fs::path config_ = dir_ / "imubridge.toml", db_ = dir_ / "run.db", tty_ = dir_ / "tty";
  Broker broker_{dir_.path()};
  std::unique_ptr<Process> daemon_;
};

const std::string kTopic = "imubridge/field-1/imu/";

TEST_F(MqttTest, SamplesAndEstimatesArriveInOrderAsTheLineStreamsJson) {
  constexpr std::size_t kFrames = 600;  // 3 s at 200 Hz
  const auto frames = simulated_frames(kFrames);
  Subscriber subscriber(broker_.port());
  write_config("sample_hz = 50\n");
  cli::PtyPair pty(tty_);
  const std::int64_t started_ns = wall_now_ns();
  start();
  ASSERT_TRUE(subscriber.wait_for("imubridge/field-1/status", 1)) << daemon_->log();
  write_paced(pty, frames);
  const int delay = pipeline::EstimationStage(estimator::ModelParams{}).delay_samples();
  const std::size_t estimates = kFrames - 2 * delay;
  ASSERT_TRUE(subscriber.wait_for(kTopic + "estimate", estimates)) << daemon_->log();
  const std::int64_t received_ns = wall_now_ns();
  stop();
  ASSERT_TRUE(subscriber.wait_for("imubridge/field-1/status", 2));

  const auto status = subscriber.on("imubridge/field-1/status");
  EXPECT_EQ(status.front().at("state"), "online");
  EXPECT_EQ(status.front().at("links"), json::array({"imu"}));
  EXPECT_EQ(status.back().at("state"), "offline") << "a clean stop says so itself";

  // What the store holds, by sequence number, to compare the payloads with.
  std::map<std::uint64_t, protocol::Sample> stored;
  for (const auto& s : committed_samples(db_)) stored[s.seq] = s;
  ASSERT_EQ(stored.size(), kFrames);

  // Samples: capped at 50 Hz of device time, so every 4th of the 200 Hz stream, in order; the line stream's fields.
  const auto samples = subscriber.on(kTopic + "sample");
  ASSERT_EQ(samples.size(), kFrames / 4);
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const json& m = samples[i];
    ASSERT_EQ(m.at("seq").get<std::uint64_t>(), 4 * i) << m;
    const protocol::Sample& s = stored.at(4 * i);
    EXPECT_EQ(m.at("link"), "imu");
    EXPECT_EQ(m.at("timestamp").get<double>(), static_cast<double>(s.device_time_us) / 1e6);
    EXPECT_EQ(m.at("accel").at("x").get<double>(), s.accel[0]);
    EXPECT_EQ(m.at("gyro").at("z").get<double>(), s.gyro[2]);
    EXPECT_EQ(m.contains("mag"), s.has_mag);
    EXPECT_FALSE(m.contains("estimate"));
    const auto recv = m.at("recv_wall_ns").get<std::int64_t>();
    EXPECT_TRUE(recv >= started_ns && recv <= received_ns) << recv;
    if (i > 0) {
      EXPECT_GE(recv, samples[i - 1].at("recv_wall_ns").get<std::int64_t>());
    }
  }

  // Estimates: every one (no cap), in order, each with the sample that completed it.
  const store::Store store(db_, {.read_only = true});
  std::vector<store::Estimate> stored_estimates;
  store.for_each_estimate(store.runs(store.sessions().at(0).id).at(0).id,
                          [&](const store::Estimate& e) { stored_estimates.push_back(e); });
  const auto published = subscriber.on(kTopic + "estimate");
  ASSERT_EQ(published.size(), estimates);
  ASSERT_EQ(stored_estimates.size(), estimates);
  for (std::size_t i = 0; i < published.size(); ++i) {
    const json& e = published[i].at("estimate");
    ASSERT_EQ(e.at("seq").get<std::uint64_t>(), i + delay);
    EXPECT_EQ(e.at("fx").get<double>(), stored_estimates[i].fx);
    EXPECT_TRUE(e.at("vx").is_null()) << "no parameters: no velocity";
    // The sample that completed it: `delay` later, or later still while the link's IMU axes were being detected.
    EXPECT_GE(published[i].at("seq").get<std::uint64_t>(), i + 2 * delay);
    if (i > 0) {
      EXPECT_GE(published[i].at("seq").get<std::uint64_t>(), published[i - 1].at("seq").get<std::uint64_t>());
    }
  }
  EXPECT_TRUE(subscriber.on(kTopic + "event").empty()) << "no gaps, no drops";
}

TEST_F(MqttTest, ABrokerRestartedMidRunCostsNoRecordedSampleAndPublishingResumes) {
  constexpr std::size_t kFrames = 900;
  const auto frames = simulated_frames(kFrames);
  const auto part = [&](std::size_t from, std::size_t to) {
    return std::vector<std::vector<std::uint8_t>>(frames.begin() + from, frames.begin() + to);
  };
  const auto seqs_of = [](const Subscriber& subscriber) {
    std::vector<std::uint64_t> seqs;
    for (const auto& m : subscriber.on(kTopic + "sample")) seqs.push_back(m.at("seq"));
    return seqs;
  };
  // Every sample (no cap to speak of), no estimates, an outbox that holds a third of what the outage brings.
  write_config("sample_hz = 100000\nestimate_hz = 0\noutbox = 100\nreconnect_min_s = 1\nreconnect_max_s = 1\n");
  cli::PtyPair pty(tty_);
  // Fifty at a time, each received before the next: far from filling the outbox, however slow the machine.
  const auto write_seen_by = [&](const Subscriber& subscriber, std::size_t from, std::size_t to) {
    for (; from < to; from += 50) {
      write_paced(pty, part(from, from + 50));
      ASSERT_TRUE(eventually([&] {
        const auto seqs = seqs_of(subscriber);
        return !seqs.empty() && seqs.back() == from + 49;
      })) << daemon_->log();
    }
  };
  start();
  ASSERT_TRUE(daemon_->wait_for_log("mqtt: connected")) << daemon_->log();
  {
    Subscriber before(broker_.port());
    write_seen_by(before, 0, 300);
    ASSERT_EQ(seqs_of(before).size(), 300u);
  }
  broker_.stop(SIGKILL);
  // Once the daemon knows (at once: the kernel closed the broker's sockets), so that none of what follows is written
  // into the dead connection and counted as lost rather than dropped.
  ASSERT_TRUE(daemon_->wait_for_log("mqtt: lost the connection to " + broker_.url())) << daemon_->log();
  write_paced(pty, part(300, 600));  // while the broker is away: recorded all the same
  ASSERT_TRUE(wait_for_samples(db_, 600)) << daemon_->log();
  broker_.start();
  Subscriber after(broker_.port());
  ASSERT_TRUE(after.wait_for("imubridge/field-1/status", 1)) << daemon_->log();
  write_seen_by(after, 600, kFrames);
  daemon_->signal(SIGUSR1);
  ASSERT_TRUE(daemon_->wait_for_log("stats {")) << daemon_->log();
  stop();

  // The store has every sample the simulator sent, in sequence.
  const auto samples = committed_samples(db_);
  ASSERT_EQ(samples.size(), kFrames);
  for (std::size_t i = 0; i < kFrames; ++i) ASSERT_EQ(samples[i].seq, i);

  // Publishing resumed, in order: the last third arrived whole, after whatever of the outage the outbox kept.
  const auto seqs = seqs_of(after);
  ASSERT_GE(seqs.size(), 300u);
  EXPECT_TRUE(std::is_sorted(seqs.begin(), seqs.end()));
  EXPECT_EQ(std::adjacent_find(seqs.begin(), seqs.end()), seqs.end()) << "no duplicates";
  for (std::size_t i = 0; i < 300; ++i) ASSERT_EQ(seqs[seqs.size() - 300 + i], 600 + i);
  EXPECT_TRUE(after.on(kTopic + "estimate").empty()) << "estimate_hz = 0 publishes none";

  // What did not fit is counted: the outage's 300 samples, less the 100 the outbox kept.
  const store::Store store(db_, {.read_only = true});
  auto totals = event_totals(store, store.sessions().at(0).id);
  EXPECT_EQ(totals["mqtt_dropped"], 200) << daemon_->log();
  EXPECT_EQ(totals["mqtt_lost"], 0);
  EXPECT_EQ(totals["mqtt_connected"], 2) << daemon_->log();
  EXPECT_EQ(totals["mqtt_disconnected"], 1);
  const std::string log = daemon_->log();
  EXPECT_NE(log.find("messages dropped (outbox of 100 full"), std::string::npos) << log;
  const auto stats =
      json::parse(log.substr(log.find("stats {") + 6, log.find('\n', log.find("stats {")) - log.find("stats {") - 6));
  const json& mqtt = stats.at("outputs").at("mqtt");
  EXPECT_EQ(mqtt.at("connects"), 2);
  EXPECT_EQ(mqtt.at("dropped"), 200);
  EXPECT_EQ(mqtt.at("lost"), 0);
}

TEST_F(MqttTest, TheLastWillSaysOfflineWhenTheDaemonIsKilled) {
  write_config("keepalive_s = 5\nprotocol_version = \"5\"\n");
  cli::PtyPair pty(tty_);
  Subscriber subscriber(broker_.port());
  start();
  ASSERT_TRUE(subscriber.wait_for("imubridge/field-1/status", 1)) << daemon_->log();
  EXPECT_EQ(subscriber.on("imubridge/field-1/status").at(0).at("state"), "online");
  daemon_->signal(SIGKILL);
  EXPECT_EQ(daemon_->wait(), -SIGKILL);
  ASSERT_TRUE(subscriber.wait_for("imubridge/field-1/status", 2)) << slurp(dir_ / "mosquitto.log");
  EXPECT_EQ(subscriber.on("imubridge/field-1/status").at(1).at("state"), "offline");

  // A screen that connects later learns it from the retained status.
  Subscriber later(broker_.port());
  ASSERT_TRUE(later.wait_for("imubridge/field-1/status", 1));
  const auto status = later.messages().at(0);
  EXPECT_TRUE(status.retained);
  EXPECT_EQ(json::parse(status.payload).at("state"), "offline");
}

TEST_F(MqttTest, ABadMqttConfigurationIsOneLineNamingTheKey) {
  const auto error_of = [&](const std::string& keys) {
    std::ofstream(config_) << "[outputs.mqtt]\n"
                           << keys << "[[link]]\nname = \"imu\"\ndevice = \"" << tty_.string() << "\"\n";
    const auto result = run_imubridge("run --config " + config_.string() + " --db " + db_.string());
    EXPECT_EQ(result.exit_code, 2) << result.err;
    EXPECT_EQ(count_lines(result.err), 1) << result.err;
    return result.err;
  };
  const std::string url = "url = \"" + broker_.url() + "\"\n";
  EXPECT_NE(error_of("url = \"http://x:1883\"\nstation = \"s\"\n").find("'outputs.mqtt.url'"), std::string::npos);
  EXPECT_NE(error_of("url = \"mqtt://x:99999\"\nstation = \"s\"\n").find("'outputs.mqtt.url'"), std::string::npos);
  EXPECT_NE(error_of(url).find("'outputs.mqtt' needs a 'station'"), std::string::npos);
  EXPECT_NE(error_of(url + "station = \"a/b\"\n").find("'outputs.mqtt.station'"), std::string::npos);
  EXPECT_NE(error_of(url + "station = \"s\"\nqos = 2\n").find("'outputs.mqtt.qos'"), std::string::npos);
  EXPECT_NE(error_of(url + "station = \"s\"\nkeepalive_s = 2\n").find("'outputs.mqtt.keepalive_s'"), std::string::npos);
  EXPECT_NE(error_of(url + "station = \"s\"\npassword = \"hunter2\"\n").find("'outputs.mqtt.password'"),
            std::string::npos);
  EXPECT_NE(error_of(url + "station = \"s\"\nqso = 1\n").find("unknown key 'outputs.mqtt.qso'"), std::string::npos);
  const std::string unset = error_of(url + "station = \"s\"\nusername = \"u\"\npassword_env = \"IMUBRIDGE_NO_SUCH\"\n");
  EXPECT_NE(unset.find("outputs.mqtt.password_env"), std::string::npos) << unset;
  EXPECT_NE(unset.find("IMUBRIDGE_NO_SUCH"), std::string::npos) << unset;
}

TEST_F(MqttTest, QoS1AndAnEstimateCap) {
  constexpr std::size_t kFrames = 600;  // 3 s at 200 Hz
  Subscriber subscriber(broker_.port());
  write_config("qos = 1\nsample_hz = 0\nestimate_hz = 100\n");
  cli::PtyPair pty(tty_);
  start();
  write_paced(pty, simulated_frames(kFrames));
  ASSERT_TRUE(wait_for_samples(db_, kFrames)) << daemon_->log();
  write_config("qos = 0\n");
  daemon_->signal(SIGHUP);
  ASSERT_TRUE(daemon_->wait_for_log("SIGHUP: [outputs.mqtt] changed; MQTT goes on as started")) << daemon_->log();
  stop();
  ASSERT_TRUE(subscriber.wait_for("imubridge/field-1/status", 2));
  EXPECT_TRUE(subscriber.on(kTopic + "sample").empty()) << "sample_hz = 0 publishes none";
  // Every estimate went (QoS 1, and the clean stop waits for the outbox), at most one per 10 ms of device time.
  const auto estimates = subscriber.on(kTopic + "estimate");
  ASSERT_GE(estimates.size(), 2u);
  for (std::size_t i = 1; i < estimates.size(); ++i) {
    EXPECT_GE(estimates[i].at("timestamp").get<double>() - estimates[i - 1].at("timestamp").get<double>(), 0.00999);
    EXPECT_GT(estimates[i].at("estimate").at("seq").get<std::uint64_t>(),
              estimates[i - 1].at("estimate").at("seq").get<std::uint64_t>());
  }
  const double span = estimates.back().at("timestamp").get<double>() - estimates.front().at("timestamp").get<double>();
  EXPECT_GE(estimates.size(), static_cast<std::size_t>(span * 100 * 0.9)) << "the cap, not fewer";
  const std::string log = daemon_->log();
  const auto stats = json::parse(
      log.substr(log.rfind("stats {") + 6, log.find('\n', log.rfind("stats {")) - log.rfind("stats {") - 6));
  EXPECT_EQ(stats.at("outputs").at("mqtt").at("published"), estimates.size());
}

// mqtts:// to a broker whose certificate a private CA signed: trusted with ca_file, refused with another CA, and the
// recording goes on either way.
TEST(MqttTls, APrivateCaIsTrustedWithCaFileAndAnotherIsRefused) {
  TempDir dir;
  ASSERT_EQ(std::system(("exec >/dev/null 2>&1; cd " + dir.path().string() +
                         " && for ca in ca other; do openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1"
                         " -nodes -keyout $ca.key -out $ca.crt -days 2 -subj /CN=$ca; done"
                         " && openssl req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -keyout server.key"
                         " -out server.csr -subj /CN=localhost"
                         " && printf 'subjectAltName=IP:127.0.0.1,DNS:localhost\\n' > san.ext"
                         " && openssl x509 -req -in server.csr -CA ca.crt -CAkey ca.key -CAcreateserial"
                         " -out server.crt -days 2 -extfile san.ext"
                         // mosquitto, started as root, reads them as the user "mosquitto"
                         " && chmod 755 . && chmod 644 *")
                            .c_str()),
            0);
  Broker broker(dir.path(), "allow_anonymous true\ncafile " + (dir / "ca.crt").string() + "\ncertfile " +
                                (dir / "server.crt").string() + "\nkeyfile " + (dir / "server.key").string() + "\n");
  Subscriber subscriber(broker.port(), dir / "ca.crt");
  const auto run_with = [&](const std::string& ca, const std::string& db) {
    std::ofstream(dir / "imubridge.toml")
        << "[store]\npath = \"" << (dir / db).string() << "\"\nmin_free_mib = 0\n"
        << "[outputs.mqtt]\nurl = \"mqtts://127.0.0.1:" << broker.port() << "\"\nstation = \"field-1\"\nca_file = \""
        << (dir / ca).string() << "\"\nreconnect_min_s = 1\nreconnect_max_s = 1\n"
        << "[[link]]\nname = \"imu\"\ndevice = \"" << (dir / "tty").string() << "\"\n";
    return std::make_unique<Process>(std::vector<std::string>{"run", "--config", (dir / "imubridge.toml").string()},
                                     dir / (db + ".stderr"));
  };
  cli::PtyPair pty(dir / "tty");
  {
    auto daemon = run_with("ca.crt", "trusted.db");
    ASSERT_TRUE(subscriber.wait_for("imubridge/field-1/status", 1)) << daemon->log();
    ASSERT_TRUE(daemon->wait_for_log("link 'imu': reading")) << daemon->log();
    write_paced(pty, simulated_frames(200));
    ASSERT_TRUE(subscriber.wait_for(kTopic + "estimate", 1)) << daemon->log();
    daemon->signal(SIGTERM);
    ASSERT_EQ(daemon->wait(), 0) << daemon->log();
  }
  ASSERT_TRUE(subscriber.wait_for("imubridge/field-1/status", 2)) << "online, then offline";
  const std::size_t statuses = subscriber.on("imubridge/field-1/status").size();
  auto daemon = run_with("other.crt", "refused.db");
  ASSERT_TRUE(daemon->wait_for_log("certificate verify failed")) << daemon->log();
  ASSERT_TRUE(daemon->wait_for_log("link 'imu': reading")) << daemon->log();
  write_paced(pty, simulated_frames(200));
  EXPECT_TRUE(wait_for_samples(dir / "refused.db", 200)) << daemon->log();
  EXPECT_EQ(count_of(daemon->log(), "certificate verify failed"), 1) << "said once, not at every attempt";
  EXPECT_EQ(subscriber.on("imubridge/field-1/status").size(), statuses) << "never connected";
}

// A broker that wants a login: the password from password_env or password_file logs in; a wrong one is refused,
// said in the log without the password.
TEST(MqttLogin, ThePasswordFromTheEnvironmentOrAFileLogsInAndAWrongOneIsRefused) {
  TempDir dir;
  ASSERT_EQ(std::system(("exec >/dev/null 2>&1; cd " + dir.path().string() +
                         " && mosquitto_passwd -c -b passwd field-1 s3cret-pw && printf 's3cret-pw\\n' > pw.txt"
                         " && chmod 755 . && chmod 644 passwd")  // mosquitto reads it as the user "mosquitto"
                            .c_str()),
            0);
  Broker broker(dir.path(), "allow_anonymous false\npassword_file " + (dir / "passwd").string() + "\n");
  int runs = 0;
  const auto run_with = [&](const std::string& password_keys, const std::string& password_env_value) {
    std::ofstream(dir / "imubridge.toml")
        << "[store]\npath = \"" << (dir / "run.db").string() << "\"\nmin_free_mib = 0\n[outputs.mqtt]\nurl = \""
        << broker.url() << "\"\nstation = \"field-1\"\nusername = \"field-1\"\n"
        << password_keys << "reconnect_min_s = 1\nreconnect_max_s = 1\n"
        << "[[link]]\nname = \"imu\"\ndevice = \"" << (dir / "tty").string() << "\"\n";
    return std::make_unique<Process>(
        std::vector<std::string>{"run", "--config", (dir / "imubridge.toml").string()},
        dir / ("stderr" + std::to_string(++runs)),
        SpawnOptions{.env = {{"IMUBRIDGE_TEST_MQTT_PASSWORD", password_env_value}}, .file_size_limit = std::nullopt});
  };
  for (const std::string& keys : {std::string("password_env = \"IMUBRIDGE_TEST_MQTT_PASSWORD\"\n"),
                                  "password_file = \"" + (dir / "pw.txt").string() + "\"\n"}) {
    auto daemon = run_with(keys, "s3cret-pw");
    EXPECT_TRUE(daemon->wait_for_log("mqtt: connected to " + broker.url())) << keys << daemon->log();
    daemon->signal(SIGTERM);
    EXPECT_EQ(daemon->wait(), 0) << daemon->log();
  }
  auto daemon = run_with("password_env = \"IMUBRIDGE_TEST_MQTT_PASSWORD\"\n", "wrong-pw");
  ASSERT_TRUE(daemon->wait_for_log("mqtt: " + broker.url() +
                                   " refused the connection: Connection Refused: not "
                                   "authorised."))
      << daemon->log();
  daemon->signal(SIGTERM);
  EXPECT_EQ(daemon->wait(), 0) << daemon->log();
  EXPECT_EQ(daemon->log().find("wrong-pw"), std::string::npos) << daemon->log();
  EXPECT_EQ(slurp(dir / "imubridge.toml").find("pw"), std::string::npos) << "only where the password is";

  // Under MQTT 5 a refusal ends libmosquitto's own loop (an error, not a refusal, to it): the sink tries again all
  // the same, and says so once.
  const auto attempts = [&] { return count_of(slurp(dir / "mosquitto.log"), "New connection from 127.0.0.1"); };
  daemon = run_with("password_env = \"IMUBRIDGE_TEST_MQTT_PASSWORD\"\nprotocol_version = \"5\"\n", "wrong-pw");
  ASSERT_TRUE(daemon->wait_for_log("refused the connection: Not authorized")) << daemon->log();
  const int before = attempts();
  EXPECT_TRUE(eventually([&] { return attempts() >= before + 2; })) << slurp(dir / "mosquitto.log");
  daemon->signal(SIGTERM);
  EXPECT_EQ(daemon->wait(), 0) << daemon->log();
  EXPECT_EQ(count_of(daemon->log(), "refused the connection"), 1) << daemon->log();
}

// The table as written is what a session records of it (to_toml), the password's source but never the password.
TEST(MqttConfig, ReadsEveryKeyAndRecordsThemBack) {
  const auto config = daemon::parse_config(R"([outputs.mqtt]
url = "mqtts://broker.lab:8884"
station = "field-2"
qos = 1
sample_hz = 25
estimate_hz = 100
keepalive_s = 10
reconnect_min_s = 2
reconnect_max_s = 60
outbox = 1000
username = "gs"
password_file = "/etc/imubridge/mqtt.password"
ca_file = "/etc/imubridge/ca.pem"
protocol_version = "5"
)",
                                           "test.toml");
  ASSERT_TRUE(config.outputs.mqtt.has_value());
  const daemon::MqttConfig& m = *config.outputs.mqtt;
  EXPECT_EQ(m.host, "broker.lab");
  EXPECT_EQ(m.port, 8884);
  EXPECT_TRUE(m.tls);
  EXPECT_EQ(m.qos, 1);
  EXPECT_EQ(m.estimate_hz, 100.0);
  EXPECT_EQ(m.client_id, "imubridge-field-2");
  EXPECT_EQ(m.protocol_version, 5);
  EXPECT_EQ(daemon::parse_config(daemon::to_toml(config), "snapshot").outputs.mqtt, m);

  const auto plain = daemon::parse_config("[outputs.mqtt]\nurl = \"mqtt://[::1]\"\nstation = \"s\"\n", "t.toml");
  EXPECT_EQ(plain.outputs.mqtt->host, "::1");
  EXPECT_EQ(plain.outputs.mqtt->port, 1883);
  EXPECT_EQ(plain.outputs.mqtt->sample_hz, 50.0);
  EXPECT_FALSE(plain.outputs.mqtt->estimate_hz.has_value()) << "every estimate";
}

}  // namespace
}  // namespace imubridge::test
