#pragma once
// Live telemetry to an MQTT broker, for screens beyond the ground station's own: each link's samples, estimates and
// events under imubridge/<station>/<link>/..., and the station's retained status with a last will, through
// libmosquitto. Topics, payloads, decimation and the outbox: docs/outputs.md, "MQTT".
//
// The recording never waits for the broker. on_sample, on the daemon's thread, only decimates, writes the JSON and
// appends it to a bounded outbox (the oldest message goes when it is full, and is counted); a thread of the sink's own
// hands the outbox to libmosquitto, and another runs libmosquitto's loop: it connects, sends, and reconnects with
// backoff after any failure. Drops are logged, recorded as session events and published as events once the broker
// is back.
#include <array>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "daemon/asio.hpp"
#include "daemon/config.hpp"
#include "daemon/telemetry_feed.hpp"
#include "pipeline/session_engine.hpp"

struct mosquitto;

namespace imubridge::daemon {

class Outputs;
struct LiveContext;
struct LiveLink;

// The password that password_file or password_env names, or none when neither is set. Throws std::invalid_argument
// naming the key when the file cannot be read or the variable is not set; the message never holds the password.
std::optional<std::string> read_mqtt_password(const MqttConfig& config);

class MqttSink final : public pipeline::SessionSink {
 public:
  // Connects in the background: a broker that is down at start is tried again as one lost later. Throws
  // std::invalid_argument for a password that cannot be read or TLS files libmosquitto cannot load.
  MqttSink(const MqttConfig& config, const std::vector<LiveLink>& links, const LiveContext& context);
  // Gives what waits in the outbox a moment (kFlushLimit) to go, says "offline" on the status and disconnects.
  ~MqttSink() override;
  MqttSink(const MqttSink&) = delete;
  MqttSink& operator=(const MqttSink&) = delete;

  void on_sample(std::size_t link, const protocol::Sample& sample, std::span<const store::Estimate> estimates,
                 std::int64_t recv_mono_ns) override;

  // From any thread: what the stats line shows under outputs.mqtt.
  nlohmann::json counters() const;

 private:
  using Topic = TelemetryFeed::Kind;
  struct Message {
    std::uint32_t link;
    Topic topic;
    std::string payload;
  };

  // Construction's steps: the topics and status payloads, by link; the libmosquitto client and its options (it is
  // destroyed again when one fails); its callbacks; the first connection attempt.
  void name_topics();
  void create_client(const std::optional<std::string>& password);
  void set_callbacks();
  void start_connecting();
  void publish_event(std::size_t link, const std::string& kind, std::int64_t count, const std::string& detail,
                     std::optional<std::int64_t> device_time_us, std::int64_t wall_ns, bool evicts = true);
  // Appends to the outbox, dropping the oldest beyond its bound. A report of drops (`evicts` false) goes in over
  // the bound instead: the message saying that data was dropped must not drop more of it. The next message that
  // evicts brings the outbox back within its bound.
  void enqueue(std::size_t link, Topic topic, std::string payload, bool evicts = true);
  void publish_loop();
  void network_loop();
  void on_error(const char* text);
  void report();
  void schedule_report();
  void on_connect(int rc);
  void on_disconnect(int rc);
  void on_publish(int mid);

  MqttConfig config_;
  TelemetryFeed feed_;                                                  // daemon thread only
  std::vector<std::array<std::string, TelemetryFeed::kKinds>> topics_;  // by link and Topic
  std::string status_topic_, online_payload_, offline_payload_;
  std::vector<std::uint64_t> drops_to_publish_;  // by link; daemon thread only
  std::string last_error_logged_;                // libmosquitto's last error message; daemon thread only
  boost::asio::io_context& io_;                  // the daemon's: logs, events and the report timer happen on its thread
  Outputs& outputs_;
  std::function<void(std::optional<std::size_t>, std::string, std::string, std::int64_t)> record_event_;
  boost::asio::steady_timer report_timer_;
  mosquitto* client_ = nullptr;

  // Shared by the daemon's thread, the publishing thread and libmosquitto's: all below, under mutex_.
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::deque<Message> outbox_;
  bool connected_ = false;
  bool stopping_ = false;      // the publishing thread stops
  bool closing_ = false;       // the connection thread reconnects no more
  bool abandon_ = false;       // the connection thread ends, connected or not
  std::size_t in_flight_ = 0;  // handed to libmosquitto and not yet written (QoS 0) or acknowledged (QoS 1)
  int status_mid_ = -1;        // the status message in flight, which is not the outbox's
  std::vector<std::uint64_t> dropped_unreported_;  // by link: outbox overflow since the last report
  std::uint64_t lost_unreported_ = 0;              // QoS 0 messages libmosquitto still held when the connection broke
  std::uint64_t enqueued_ = 0, published_ = 0, dropped_ = 0, lost_ = 0, connects_ = 0, disconnects_ = 0;
  std::thread network_, publisher_;
};

}  // namespace imubridge::daemon
