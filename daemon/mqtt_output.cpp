#include "daemon/mqtt_output.hpp"

#include <mosquitto.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <stdexcept>
#include <utility>

#include "daemon/daemon_internal.hpp"
#include "daemon/live_sinks.hpp"
#include "daemon/outputs.hpp"

namespace imubridge::daemon {
namespace {

using namespace std::chrono_literals;

// Messages handed to libmosquitto and not yet written or acknowledged. Its own queue has no bound, so a slow broker
// would grow it without limit: the bound is the outbox's, and this keeps libmosquitto's share small.
constexpr std::size_t kInFlightWindow = 64;
// How often drops are logged, recorded and published while they go on.
constexpr auto kReportInterval = 5s;
// At shutdown, how long what waits in the outbox may take to reach a connected broker.
constexpr auto kFlushLimit = 1s;
// The connection thread's longest wait for the socket; also how long stopping may wait for it.
constexpr auto kLoopTimeout = 500ms;

void check(int rc, const std::string& what) {
  if (rc != MOSQ_ERR_SUCCESS) throw std::invalid_argument(what + ": " + mosquitto_strerror(rc));
}

}  // namespace

std::optional<std::string> read_mqtt_password(const MqttConfig& config) {
  if (config.password_file) {
    std::ifstream in(*config.password_file);
    std::string password;
    if (!in || !std::getline(in, password)) {
      throw std::invalid_argument("outputs.mqtt.password_file '" + config.password_file->string() +
                                  "': cannot read the password from it");
    }
    if (!password.empty() && password.back() == '\r') password.pop_back();
    return password;
  }
  if (config.password_env) {
    const char* password = std::getenv(config.password_env->c_str());
    if (!password) {
      throw std::invalid_argument("outputs.mqtt.password_env: the environment variable '" + *config.password_env +
                                  "' is not set");
    }
    return std::string(password);
  }
  return std::nullopt;
}

MqttSink::MqttSink(const MqttConfig& config, const std::vector<LiveLink>& links, const LiveContext& context)
    : config_(config),
      feed_(links, config.sample_hz, config.estimate_hz,
            [this](std::size_t link, Topic topic, std::string payload, std::int64_t) {
              enqueue(link, topic, std::move(payload));
            }),
      io_(context.io),
      outputs_(context.outputs),
      record_event_(context.record_event),
      report_timer_(context.io) {
  name_topics();
  const auto password = read_mqtt_password(config_);
  create_client(password);
  set_callbacks();
  start_connecting();
  network_ = std::thread([this] { network_loop(); });
  publisher_ = std::thread([this] { publish_loop(); });
  outputs_.add_counters("mqtt", [this] { return counters(); });
  schedule_report();
  spdlog::info("mqtt: publishing to {} as station '{}' (samples {}, estimates {}, QoS {})", config_.url,
               config_.station,
               config_.sample_hz <= 0 ? std::string("off") : fmt::format("at most {} Hz per link", config_.sample_hz),
               !config_.estimate_hz        ? std::string("all")
               : *config_.estimate_hz <= 0 ? std::string("off")
                                           : fmt::format("at most {} Hz per link", *config_.estimate_hz),
               config_.qos);
}

void MqttSink::name_topics() {
  const std::vector<std::string>& link_names = feed_.link_names();
  dropped_unreported_.assign(link_names.size(), 0);
  drops_to_publish_.assign(link_names.size(), 0);
  const std::string root = "imubridge/" + config_.station + "/";
  for (const std::string& link : link_names) {
    topics_.push_back({root + link + "/sample", root + link + "/estimate", root + link + "/event"});
  }
  status_topic_ = root + "status";
  offline_payload_ = nlohmann::json{{"state", "offline"}, {"station", config_.station}}.dump();
  online_payload_ = nlohmann::json{{"state", "online"},
                                   {"station", config_.station},
                                   {"links", link_names},
                                   {"software_version", IMUBRIDGE_VERSION},
                                   {"pid", static_cast<std::int64_t>(::getpid())}}
                        .dump();
}

void MqttSink::create_client(const std::optional<std::string>& password) {
  static std::once_flag library;
  std::call_once(library, [] { mosquitto_lib_init(); });
  client_ = mosquitto_new(config_.client_id.c_str(), /*clean_session=*/true, this);
  if (!client_) throw std::runtime_error("mqtt: cannot create a client");
  try {
    check(mosquitto_int_option(client_, MOSQ_OPT_PROTOCOL_VERSION,
                               config_.protocol_version == 5 ? MQTT_PROTOCOL_V5 : MQTT_PROTOCOL_V311),
          "outputs.mqtt.protocol_version");
    // Live telemetry is many small messages: Nagle's algorithm would hold each behind the broker's delayed ACK of
    // the one before, tens of milliseconds on a quiet link.
    check(mosquitto_int_option(client_, MOSQ_OPT_TCP_NODELAY, 1), "outputs.mqtt: TCP_NODELAY");
    // The broker says "offline" for a station that dies without a word: killed, its machine or network gone.
    check(mosquitto_will_set(client_, status_topic_.c_str(), static_cast<int>(offline_payload_.size()),
                             offline_payload_.data(), 1, /*retain=*/true),
          "outputs.mqtt: the last will");
    if (config_.username) {
      check(mosquitto_username_pw_set(client_, config_.username->c_str(), password ? password->c_str() : nullptr),
            "outputs.mqtt.username");
    }
    if (config_.tls) {
      if (config_.ca_file) {
        check(mosquitto_tls_set(client_, config_.ca_file->c_str(), nullptr, nullptr, nullptr, nullptr),
              "outputs.mqtt.ca_file '" + config_.ca_file->string() + "'");
      } else {
        check(mosquitto_int_option(client_, MOSQ_OPT_TLS_USE_OS_CERTS, 1), "outputs.mqtt: the system's CAs");
      }
    }
  } catch (...) {
    mosquitto_destroy(client_);
    throw;
  }
}

void MqttSink::set_callbacks() {
  mosquitto_connect_callback_set(client_,
                                 [](mosquitto*, void* self, int rc) { static_cast<MqttSink*>(self)->on_connect(rc); });
  mosquitto_disconnect_callback_set(
      client_, [](mosquitto*, void* self, int rc) { static_cast<MqttSink*>(self)->on_disconnect(rc); });
  mosquitto_publish_callback_set(
      client_, [](mosquitto*, void* self, int mid) { static_cast<MqttSink*>(self)->on_publish(mid); });

  mosquitto_log_callback_set(client_, [](mosquitto*, void* self, int level, const char* text) {
    if (level == MOSQ_LOG_ERR) static_cast<MqttSink*>(self)->on_error(text);
  });
  // Another thread runs the connection (network_loop): mosquitto_publish only queues, and wakes it.
  mosquitto_threaded_set(client_, true);
}

void MqttSink::start_connecting() {
  // A broker that is down now is no error: network_loop keeps trying, with backoff.
  const int rc =
      mosquitto_connect_async(client_, config_.host.c_str(), config_.port, static_cast<int>(config_.keepalive.count()));
  if (rc == MOSQ_ERR_INVAL) {
    mosquitto_destroy(client_);
    throw std::invalid_argument("outputs.mqtt.url '" + config_.url + "': libmosquitto refuses it");
  }
  if (rc != MOSQ_ERR_SUCCESS) {
    spdlog::warn("mqtt: cannot reach {} yet ({}); trying again in the background", config_.url,
                 rc == MOSQ_ERR_ERRNO ? std::strerror(errno) : mosquitto_strerror(rc));
  }
}

MqttSink::~MqttSink() {
  outputs_.remove_counters("mqtt");
  report_timer_.cancel();
  bool connected = false;
  {
    std::unique_lock lock(mutex_);
    changed_.wait_for(lock, kFlushLimit, [&] { return !connected_ || (outbox_.empty() && in_flight_ == 0); });
    stopping_ = true;
    connected = connected_;
    if (!outbox_.empty() || in_flight_ > 0) {
      spdlog::warn("mqtt: {} messages not sent at shutdown", outbox_.size() + in_flight_);
    }
  }
  changed_.notify_all();
  publisher_.join();
  {
    std::lock_guard lock(mutex_);
    closing_ = true;  // no reconnecting from now on
  }
  if (connected) {
    // A station that stops cleanly says so itself: the broker keeps the last will for stations that die.
    mosquitto_publish(client_, nullptr, status_topic_.c_str(), static_cast<int>(offline_payload_.size()),
                      offline_payload_.data(), 1, true);
  }
  mosquitto_disconnect(client_);
  {
    // The DISCONNECT goes out and the connection closes; a broker that stopped reading gets kFlushLimit.
    std::unique_lock lock(mutex_);
    changed_.wait_for(lock, kFlushLimit, [&] { return !connected_; });
    abandon_ = true;
  }
  changed_.notify_all();
  network_.join();  // at most a select's timeout (kLoopTimeout) away
  mosquitto_destroy(client_);
}

// The sink's connection thread: libmosquitto's loop, and reconnection after any failure. Not mosquitto_loop_start:
// its loop gives up for good after a TLS error or an MQTT 5 refusal, and its wait between attempts cannot be cut
// short at shutdown.
void MqttSink::network_loop() {
  std::unique_lock lock(mutex_);
  int failures = 0;
  std::string last_failure;
  while (!abandon_) {
    lock.unlock();
    int rc = mosquitto_loop(client_, static_cast<int>(kLoopTimeout.count()), 1);
    lock.lock();
    if (rc == MOSQ_ERR_SUCCESS) {
      if (connected_) failures = 0;
      continue;
    }
    if (closing_) break;
    // Lost, refused, or never made: try again after reconnect_min, then twice as long each time, up to reconnect_max.
    const auto delay = std::min<std::chrono::milliseconds>(config_.reconnect_max,
                                                           config_.reconnect_min * (1 << std::min(failures, 16)));
    ++failures;
    changed_.wait_for(lock, delay, [&] { return closing_ || abandon_; });
    if (closing_ || abandon_) break;
    lock.unlock();
    rc = mosquitto_reconnect_async(client_);
    lock.lock();
    if (rc != MOSQ_ERR_SUCCESS) {
      const std::string failure = rc == MOSQ_ERR_ERRNO ? std::strerror(errno) : mosquitto_strerror(rc);
      if (failure != last_failure) {  // said once, not at every attempt
        last_failure = failure;
        boost::asio::post(io_, [this, failure] {
          spdlog::warn("mqtt: cannot connect to {}: {}; trying again, every {} s at most", config_.url, failure,
                       config_.reconnect_max.count());
        });
      }
    } else {
      last_failure.clear();
    }
  }
}

void MqttSink::on_error(const char* text) {
  std::string message(text);
  boost::asio::post(io_, [this, message = std::move(message)] {
    if (message == last_error_logged_) return;  // a broker refusing every attempt alike is said once
    last_error_logged_ = message;
    spdlog::warn("mqtt: {}", message);
  });
}

void MqttSink::on_sample(std::size_t link, const protocol::Sample& sample, std::span<const store::Estimate> estimates,
                         std::int64_t recv_mono_ns) {
  try {
    feed_.on_sample(link, sample, estimates, recv_mono_ns);
  } catch (const std::exception& e) {  // out of memory: this output misses a sample, the recording goes on
    spdlog::error("mqtt: {}", e.what());
  }
}

void MqttSink::publish_event(std::size_t link, const std::string& kind, std::int64_t count, const std::string& detail,
                             std::optional<std::int64_t> device_time_us, std::int64_t wall_ns, bool evicts) {
  enqueue(link, Topic::event, feed_.event_payload(link, kind, count, detail, device_time_us, wall_ns), evicts);
}

void MqttSink::enqueue(std::size_t link, Topic topic, std::string payload, bool evicts) {
  std::lock_guard lock(mutex_);
  while (evicts && !outbox_.empty() && outbox_.size() >= config_.outbox) {
    ++dropped_unreported_[outbox_.front().link];
    ++dropped_;
    outbox_.pop_front();
  }
  outbox_.push_back({static_cast<std::uint32_t>(link), topic, std::move(payload)});
  ++enqueued_;
  if (connected_ && in_flight_ < kInFlightWindow) changed_.notify_all();
}

// The sink's own thread: the outbox to libmosquitto, in order, as fast as the connection takes it.
void MqttSink::publish_loop() {
  std::unique_lock lock(mutex_);
  while (true) {
    changed_.wait(lock, [&] { return stopping_ || (connected_ && !outbox_.empty() && in_flight_ < kInFlightWindow); });
    if (stopping_) return;
    Message message = std::move(outbox_.front());
    outbox_.pop_front();
    ++in_flight_;
    lock.unlock();
    const std::string& topic = topics_[message.link][static_cast<std::size_t>(message.topic)];
    const int rc = mosquitto_publish(client_, nullptr, topic.c_str(), static_cast<int>(message.payload.size()),
                                     message.payload.data(), config_.qos, false);
    lock.lock();
    if (rc != MOSQ_ERR_SUCCESS) {  // the connection broke meanwhile
      in_flight_ = in_flight_ > 0 ? in_flight_ - 1 : 0;
      ++lost_unreported_;
      ++lost_;
    }
  }
}

void MqttSink::on_connect(int rc) {
  if (rc == 0) {
    int mid = 0;
    mosquitto_publish(client_, &mid, status_topic_.c_str(), static_cast<int>(online_payload_.size()),
                      online_payload_.data(), 1, true);
    {
      std::lock_guard lock(mutex_);
      status_mid_ = mid;
      connected_ = true;
      ++connects_;
      // QoS 0 messages libmosquitto held when the connection broke were dropped as it reconnected, unannounced.
      if (config_.qos == 0 && in_flight_ > 0) {
        lost_unreported_ += in_flight_;
        lost_ += in_flight_;
        in_flight_ = 0;
      }
    }
    changed_.notify_all();
  }
  boost::asio::post(io_, [this, rc] {
    if (rc != 0) {
      const std::string refusal =
          fmt::format("{} refused the connection: {}", config_.url,
                      config_.protocol_version == 5 ? mosquitto_reason_string(rc) : mosquitto_connack_string(rc));
      if (refusal != last_error_logged_) spdlog::warn("mqtt: {}", refusal);  // said once, not at every attempt
      last_error_logged_ = refusal;
      return;
    }
    spdlog::info("mqtt: connected to {}", config_.url);
    last_error_logged_.clear();
    record_event_(std::nullopt, "mqtt_connected", config_.url, 1);
    report();  // what was dropped while away, now that it can be published
  });
}

void MqttSink::on_disconnect(int rc) {
  {
    std::lock_guard lock(mutex_);
    if (!connected_) return;
    connected_ = false;
    ++disconnects_;
  }
  changed_.notify_all();
  if (rc == 0) return;  // our own disconnect, at shutdown
  boost::asio::post(io_, [this, rc] {
    spdlog::warn("mqtt: lost the connection to {} ({}); reconnecting", config_.url,
                 rc == MOSQ_ERR_ERRNO ? std::strerror(errno) : mosquitto_strerror(rc));
    record_event_(std::nullopt, "mqtt_disconnected", mosquitto_strerror(rc), 1);
  });
}

void MqttSink::on_publish(int mid) {
  {
    std::lock_guard lock(mutex_);
    if (mid == status_mid_) return;
    if (in_flight_ > 0) --in_flight_;
    ++published_;
  }
  changed_.notify_all();
}

void MqttSink::schedule_report() {
  report_timer_.expires_after(kReportInterval);
  report_timer_.async_wait([this](const boost::system::error_code& ec) {
    if (ec) return;
    report();
    schedule_report();
  });
}

// Drops since the last report: logged and recorded as session events at once, and published on each link's event
// topic once connected (while the broker is away they would only push more of the outbox out).
void MqttSink::report() {
  std::vector<std::uint64_t> dropped(feed_.link_names().size(), 0);
  std::uint64_t lost = 0, dropped_total = 0, lost_total = 0;
  bool connected = false;
  {
    std::lock_guard lock(mutex_);
    connected = connected_;
    dropped.swap(dropped_unreported_);
    lost = std::exchange(lost_unreported_, 0);
    dropped_total = dropped_;
    lost_total = lost_;
  }
  std::uint64_t dropped_now = 0;
  for (const auto n : dropped) dropped_now += n;
  if (dropped_now > 0 || lost > 0) {
    spdlog::warn(
        "mqtt: {} messages dropped (outbox of {} full: the broker was away or slow) and {} lost with a broken "
        "connection since the last report; {} and {} in all",
        dropped_now, config_.outbox, lost, dropped_total, lost_total);
  }
  for (std::size_t link = 0; link < dropped.size(); ++link) {
    if (dropped[link] == 0) continue;
    record_event_(link, "mqtt_dropped", "outbox full: the oldest messages were dropped",
                  static_cast<std::int64_t>(dropped[link]));
    drops_to_publish_[link] += dropped[link];
  }
  if (lost > 0) {
    record_event_(std::nullopt, "mqtt_lost", "QoS 0 messages libmosquitto held when the connection broke",
                  static_cast<std::int64_t>(lost));
  }
  if (!connected) return;
  const std::int64_t wall_ns = wall_now_ns();
  for (std::size_t link = 0; link < drops_to_publish_.size(); ++link) {
    if (drops_to_publish_[link] == 0) continue;
    publish_event(link, "mqtt_dropped", static_cast<std::int64_t>(std::exchange(drops_to_publish_[link], 0)),
                  "messages of this link dropped from the outbox while the broker was away or slow", std::nullopt,
                  wall_ns, /*evicts=*/false);
  }
}

nlohmann::json MqttSink::counters() const {
  std::lock_guard lock(mutex_);
  return {{"url", config_.url},       {"station", config_.station},  {"connected", connected_},
          {"connects", connects_},    {"disconnects", disconnects_}, {"enqueued", enqueued_},
          {"published", published_},  {"dropped", dropped_},         {"lost", lost_},
          {"queued", outbox_.size()}, {"in_flight", in_flight_}};
}

}  // namespace imubridge::daemon
