#pragma once
// What the network outputs that carry each link's samples, estimates and events as messages of their own (MQTT,
// Foxglove) share, on the daemon's thread: each link's messages capped at a rate of device time, the sequence gaps
// and device restarts a subscriber is told of as events, and the wall-clock time each chunk arrived. The payloads are
// the line streams' JSON plus `recv_wall_ns` (docs/outputs.md, "MQTT"); the output decides where each goes.
#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "protocol/sample.hpp"
#include "store/records.hpp"

namespace imubridge::daemon {

struct LiveLink;

class TelemetryFeed {
 public:
  enum class Kind : std::uint8_t { sample, estimate, event };
  static constexpr std::size_t kKinds = 3;
  // Every message that passes the caps, with the chunk's arrival on the wall clock.
  using Emit = std::function<void(std::size_t link, Kind kind, std::string payload, std::int64_t recv_wall_ns)>;

  // `sample_hz`, `estimate_hz`: per link, on the device clock; none: every one; 0: none.
  TelemetryFeed(const std::vector<LiveLink>& links, std::optional<double> sample_hz, std::optional<double> estimate_hz,
                Emit emit);

  void on_sample(std::size_t link, const protocol::Sample& sample, std::span<const store::Estimate> estimates,
                 std::int64_t recv_mono_ns);
  // An event message of `link`: {"timestamp" (device time, s, when known), "link", "kind", "count", "detail",
  // "wall_ns"}.
  std::string event_payload(std::size_t link, const std::string& kind, std::int64_t count, const std::string& detail,
                            std::optional<std::int64_t> device_time_us, std::int64_t wall_ns) const;
  const std::vector<std::string>& link_names() const { return link_names_; }

 private:
  // One stream of samples: a link, or one radio of an XBee link. Caps and gaps are per stream.
  struct Stream {
    protocol::SourceKey source;
    std::uint64_t last_seq;
    std::uint32_t clock_epoch;
    std::optional<std::int64_t> next_sample_us, next_estimate_us;  // device time the next one may go at
  };
  Stream& stream_of(const protocol::Sample& sample);

  std::vector<std::string> link_names_;
  // By link: whether a jump of the sequence number means samples were lost. Not on MAVLink, whose sequence numbers
  // count every message of the sender.
  std::vector<bool> counts_gaps_;
  std::int64_t sample_period_us_ = 0, estimate_period_us_ = 0;  // 0: every one; -1: none
  Emit emit_;
  std::vector<Stream> streams_;
  std::optional<std::int64_t> wall_minus_mono_ns_;  // the wall clock less the monotonic one
  std::int64_t wall_minus_mono_at_ns_ = 0;          // when (monotonic) it was taken
};

}  // namespace imubridge::daemon
