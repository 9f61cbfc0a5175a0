#pragma once
// Live outputs of `imubridge run`: every sample (with its estimate, when there is one) as JSON to PlotJuggler over
// UDP and as a line to every subscriber of a line stream. Message shapes and counters: docs/outputs.md.
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "daemon/asio.hpp"
#include "daemon/config.hpp"
#include "daemon/endpoint.hpp"
#include "protocol/sample.hpp"
#include "store/records.hpp"

namespace imubridge::daemon {

// A slow subscriber may fall this far behind (about a second of lines at 1 kHz) before its lines are dropped.
inline constexpr std::size_t kMaxQueuedBytesPerSubscriber = 256 * 1024;

// The members of a line stream's JSON object for one sample and the estimate it completed, if any (docs/outputs.md,
// "Line streams"), without the braces: `"timestamp":..,"link":..,"seq":..,...`. Other outputs with the same message
// (MQTT) add members of their own before closing it.
void append_line_members(std::string& out, std::string_view link, const protocol::Sample& sample,
                         const store::Estimate* estimate_or_null);

// Call every member from the io_context's thread. Opening a socket that fails throws std::runtime_error naming the
// endpoint; a plotjuggler endpoint that is not udp://, or a line stream that is not tcp-listen:// or unix://, throws
// std::invalid_argument.
class Outputs {
 public:
  Outputs(boost::asio::io_context& io, const OutputsConfig& config);
  ~Outputs();
  Outputs(const Outputs&) = delete;
  Outputs& operator=(const Outputs&) = delete;

  // Never blocks: a datagram that finds the send buffer full, or a line a slow subscriber has no room for, is dropped
  // and counted (the store, not the outputs, is where nothing may be lost). Each link's samples are decimated
  // separately, and an estimate goes (or is skipped) with the sample it comes with.
  void publish(std::string_view link, const protocol::Sample& sample, const store::Estimate* estimate_or_null);
  // SIGHUP: re-opens what changed and keeps the rest, subscribers included. If a new socket cannot be opened it
  // throws, and the outputs stay as they were.
  void reconfigure(const OutputsConfig& config);
  nlohmann::json counters() const;
  // The counters of an output that lives elsewhere (a sink of daemon/live_sinks.hpp), shown under `name` beside
  // these in the stats, until removed.
  void add_counters(std::string name, std::function<nlohmann::json()> counters);
  void remove_counters(std::string_view name);

 private:
  struct PlotJuggler {
    Endpoint endpoint;
    boost::asio::ip::udp::socket socket;
    boost::asio::ip::udp::endpoint target;
    std::uint64_t datagrams_sent = 0, datagrams_dropped = 0;
    std::string datagram;  // the message being sent, kept so its buffer is reused
  };

  boost::asio::io_context& io_;
  std::uint32_t decimation_ = 1;
  std::unique_ptr<PlotJuggler> plotjuggler_;
  std::vector<std::shared_ptr<StreamServer>> line_streams_;
  std::map<std::string, std::uint64_t, std::less<>> samples_seen_;  // per link, for decimation
  std::uint64_t samples_published_ = 0;
  std::map<std::string, std::function<nlohmann::json()>, std::less<>> other_counters_;
  std::optional<MqttConfig> mqtt_;  // as started: its sink (daemon/mqtt_output.hpp) keeps it until the next start
  std::optional<FoxgloveConfig> foxglove_;  // likewise (daemon/foxglove_output.hpp)
};

}  // namespace imubridge::daemon
