#pragma once
// What `imubridge run` is configured with: plain values, defaults included. The TOML file that fills them
// (/etc/imubridge/imubridge.toml) and every key's meaning: docs/config.md.
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "protocol/calibration.hpp"
#include "protocol/wire_format.hpp"

namespace imubridge::daemon {

// A network address: "udp://127.0.0.1:14550", "tcp://127.0.0.1:5760" (we connect), "tcp-listen://127.0.0.1:5760"
// (we accept), or "unix:///run/imubridge/lines.sock" (a stream socket we listen on).
struct Endpoint {
  enum class Kind { udp, tcp_connect, tcp_listen, unix_listen };
  Kind kind = Kind::udp;
  std::string host = "127.0.0.1";  // network outputs stay on loopback unless configured otherwise
  std::uint16_t port = 0;
  std::filesystem::path path;  // unix sockets
  std::string text;            // as written in the config, for messages
  friend bool operator==(const Endpoint&, const Endpoint&) = default;
};

// Which device a link reads: a path, or a USB identity found again after the device re-enumerates.
struct DeviceSelector {
  std::filesystem::path path;  // e.g. /dev/ttyUSB0, /dev/serial/by-id/..., or a pty symlink
  std::optional<std::uint16_t> usb_vid, usb_pid;
  std::optional<std::string> usb_serial;  // with vid/pid: the one radio of several identical ones
  friend bool operator==(const DeviceSelector&, const DeviceSelector&) = default;
};

struct VehicleFeedbackConfig {
  bool enabled = false;
  double rate_hz = 10.0;  // velocity estimates sent back to the vehicle, at most this often
  std::uint64_t xbee_destination64 = 0x000000000000FFFF;  // XBee links: the vehicle radio (default: broadcast)
};

struct LinkConfig {
  std::string name;  // unique; names the link in the store, logs and outputs
  DeviceSelector device;
  protocol::WireFormat format = protocol::WireFormat::imubridge;
  std::uint32_t baud = 115200;
  protocol::Calibration calibration = protocol::Calibration::reference_board();
  std::string axes = "auto";     // the IMU's axes in the body (estimator::parse_imu_axes): auto detects from gravity
  std::vector<Endpoint> bridge;  // raw bytes forwarded both ways (e.g. QGroundControl on udp://127.0.0.1:14550)
  VehicleFeedbackConfig feedback;
  std::chrono::milliseconds reconnect_min{200}, reconnect_max{5000};  // retry backoff after the port vanishes
  // MAVLink links: the IMU message samples come from (HIGHRES_IMU, SCALED_IMU, SCALED_IMU2, SCALED_IMU3, RAW_IMU)
  // and, for HIGHRES_IMU and RAW_IMU, its id. The link keeps to the first IMU heard that these admit (any without
  // them), so two IMUs never interleave (docs/protocol.md, "A live MAVLink link").
  std::optional<std::string> imu;
  std::optional<std::uint8_t> imu_id;
  // MAVLink links: message name -> Hz asked of the vehicle at every (re)open of the port (COMMAND_LONG
  // MAV_CMD_SET_MESSAGE_INTERVAL), sent as system gcs_sysid, component gcs_compid. Empty: nothing is ever sent.
  std::map<std::string, double> request_rates;
  std::uint8_t gcs_sysid = 255, gcs_compid = 190;
};

struct StoreConfig {
  std::filesystem::path path = "/var/lib/imubridge/imubridge.db";
  std::chrono::milliseconds commit_interval{200};
  std::uint64_t max_size_bytes = 0;             // 0: no cap; beyond it the database is rotated or recording stops
  std::uint64_t min_free_bytes = 256ull << 20;  // keep this much free on the disk
  enum class OnFull { rotate, stop } on_full = OnFull::rotate;
};

// Live telemetry to an MQTT broker (daemon/mqtt_output.hpp; topics, payloads and limits: docs/outputs.md, "MQTT").
// Secrets are never here: only where to read the password, since the configuration is recorded with each session.
struct MqttConfig {
  std::string url;  // as written: mqtt://HOST[:PORT] or mqtts://HOST[:PORT]
  std::string host;
  std::uint16_t port = 1883;
  bool tls = false;  // mqtts://
  std::string station;
  int qos = 0;
  double sample_hz = 50;              // per link, on the device clock; 0: no samples
  std::optional<double> estimate_hz;  // per link; none: every estimate; 0: no estimates
  std::chrono::seconds keepalive{30};
  std::chrono::seconds reconnect_min{1}, reconnect_max{30};
  std::size_t outbox = 4096;  // messages waiting for the broker; beyond it the oldest is dropped
  std::optional<std::string> username;
  std::optional<std::filesystem::path> password_file;  // the password is its first line
  std::optional<std::string> password_env;             // or the value of this environment variable
  std::optional<std::filesystem::path> ca_file;        // mqtts://: the CAs to trust; none: the system's
  std::string client_id;                               // empty: "imubridge-<station>"
  int protocol_version = 4;                            // 4: MQTT 3.1.1, 5: MQTT 5
  friend bool operator==(const MqttConfig&, const MqttConfig&) = default;
};

// [outputs.foxglove]: a Foxglove WebSocket server for Foxglove Studio (daemon/foxglove_output.hpp; channels and limits:
// docs/outputs.md, "Foxglove"). On loopback unless configured otherwise.
struct FoxgloveConfig {
  Endpoint listen{.kind = Endpoint::Kind::tcp_listen,
                  .host = "127.0.0.1",
                  .port = 8765,
                  .path = {},
                  .text = "127.0.0.1:8765"};  // Foxglove Studio's default port
  std::optional<double> sample_hz;            // per link, on the device clock; none: every sample; 0: no samples
  std::optional<double> estimate_hz;          // likewise for estimates
  std::size_t queue = 8192;                   // messages waiting for the server's thread; beyond it the oldest goes
  std::size_t client_queue_bytes = 4u << 20;  // per client, waiting to be written; beyond it its messages are dropped
  friend bool operator==(const FoxgloveConfig&, const FoxgloveConfig&) = default;
};

struct OutputsConfig {
  std::optional<Endpoint> plotjuggler{};     // JSON per sample/estimate over UDP (PlotJuggler's default 127.0.0.1:9870)
  std::vector<Endpoint> line_streams{};      // newline-delimited JSON to any subscriber (tcp-listen or unix)
  std::uint32_t decimation = 1;              // publish every Nth sample (estimates likewise)
  std::optional<MqttConfig> mqtt{};          // read at start: SIGHUP keeps the running connection
  std::optional<FoxgloveConfig> foxglove{};  // read at start: SIGHUP keeps the running server
};

// [sync]: the store copied into the fleet archive in PostgreSQL as it records (daemon/archive_sync.hpp). Like [mqtt],
// only where to read the password: the configuration is recorded with each session.
struct SyncConfig {
  std::string to;                                      // postgresql://USER@HOST[:PORT]/DB, without a password
  std::string station;                                 // the store's name in the archive; empty: the host's name
  std::chrono::seconds interval{30};                   // a pass this often
  bool chunks = false;                                 // the raw chunks too
  std::optional<std::filesystem::path> password_file;  // the password is its first line
  std::optional<std::string> password_env;             // or the value of this environment variable
  friend bool operator==(const SyncConfig&, const SyncConfig&) = default;
};

struct Config {
  std::vector<LinkConfig> links;
  StoreConfig store;
  OutputsConfig outputs;
  std::optional<SyncConfig> sync;
  std::optional<std::filesystem::path> params;  // PARAMS.json from `imubridge identify`; none: compensation only
  std::string log_level = "info";
  std::optional<std::filesystem::path> log_file;  // none: stderr (the journal under systemd); reopened on SIGHUP
  std::chrono::seconds stats_interval{60};        // counters logged this often (and on SIGUSR1)
};

}  // namespace imubridge::daemon
