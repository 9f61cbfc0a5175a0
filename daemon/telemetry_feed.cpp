#include "daemon/telemetry_feed.hpp"

#include <cmath>
#include <nlohmann/json.hpp>
#include <utility>

#include "daemon/daemon_internal.hpp"
#include "daemon/live_sinks.hpp"
#include "daemon/outputs.hpp"

namespace imubridge::daemon {
namespace {

// A rate cap as a period of device time: 0 for every message, -1 for none.
std::int64_t period_us(std::optional<double> hz) {
  if (!hz) return 0;
  if (*hz <= 0) return -1;
  return std::max<std::int64_t>(1, std::llround(1e6 / *hz));
}

// Whether a message at device time `t_us` goes out under the cap `period`, and when the next may. The slots keep to
// a grid of the period, so a cap that divides the sample rate takes exactly every Nth sample; a clock that went back
// (a device restart) starts the grid again.
bool take(std::optional<std::int64_t>& next_due_us, std::int64_t t_us, std::int64_t period) {
  if (period == 0) return true;
  if (period < 0) return false;
  if (next_due_us && t_us < *next_due_us && t_us >= *next_due_us - period) return false;
  const bool on_grid = next_due_us && t_us >= *next_due_us && t_us < *next_due_us + period;
  next_due_us = (on_grid ? *next_due_us : t_us) + period;
  return true;
}

}  // namespace

TelemetryFeed::TelemetryFeed(const std::vector<LiveLink>& links, std::optional<double> sample_hz,
                             std::optional<double> estimate_hz, Emit emit)
    : sample_period_us_(period_us(sample_hz)), estimate_period_us_(period_us(estimate_hz)), emit_(std::move(emit)) {
  for (const LiveLink& link : links) {
    link_names_.push_back(link.name);
    counts_gaps_.push_back(link.format != protocol::WireFormat::mavlink);
  }
}

TelemetryFeed::Stream& TelemetryFeed::stream_of(const protocol::Sample& sample) {
  for (Stream& stream : streams_) {
    if (stream.source == sample.source) return stream;
  }
  return streams_.emplace_back(Stream{.source = sample.source,
                                      .last_seq = sample.seq,
                                      .clock_epoch = sample.clock_epoch,
                                      .next_sample_us = std::nullopt,
                                      .next_estimate_us = std::nullopt});
}

void TelemetryFeed::on_sample(std::size_t link, const protocol::Sample& sample,
                              std::span<const store::Estimate> estimates, std::int64_t recv_mono_ns) {
  // The chunk's arrival on the wall clock, so a subscriber elsewhere can tell the end-to-end latency. The two clocks'
  // difference is taken again each second: taken at every sample, the nanoseconds between the two readings would make
  // samples of one chunk differ and later ones seem to arrive earlier.
  if (!wall_minus_mono_ns_ || recv_mono_ns - wall_minus_mono_at_ns_ >= 1'000'000'000) {
    wall_minus_mono_ns_ = wall_now_ns() - mono_now_ns();
    wall_minus_mono_at_ns_ = recv_mono_ns;
  }
  const std::int64_t recv_wall_ns = recv_mono_ns + *wall_minus_mono_ns_;
  Stream& stream = stream_of(sample);
  if (sample.clock_epoch != stream.clock_epoch) {
    emit_(link, Kind::event,
          event_payload(link, "device_restart", 1, "the device's sequence number and clock went back",
                        sample.device_time_us, recv_wall_ns),
          recv_wall_ns);
    stream.next_sample_us.reset();
    stream.next_estimate_us.reset();
  } else if (counts_gaps_[link] && sample.seq > stream.last_seq + 1) {
    emit_(link, Kind::event,
          event_payload(link, "sequence_gap", static_cast<std::int64_t>(sample.seq - stream.last_seq - 1),
                        "samples lost before reaching the ground station", sample.device_time_us, recv_wall_ns),
          recv_wall_ns);
  }
  stream.clock_epoch = sample.clock_epoch;
  stream.last_seq = sample.seq;

  const std::string_view name = link_names_.at(link);
  const auto message = [&](const store::Estimate* estimate) {
    std::string json = "{";
    append_line_members(json, name, sample, estimate);
    json += ",\"recv_wall_ns\":";
    json += std::to_string(recv_wall_ns);
    json += '}';
    return json;
  };
  if (take(stream.next_sample_us, sample.device_time_us, sample_period_us_)) {
    emit_(link, Kind::sample, message(nullptr), recv_wall_ns);
  }
  for (const store::Estimate& estimate : estimates) {
    if (take(stream.next_estimate_us, sample.device_time_us, estimate_period_us_)) {
      emit_(link, Kind::estimate, message(&estimate), recv_wall_ns);
    }
  }
}

std::string TelemetryFeed::event_payload(std::size_t link, const std::string& kind, std::int64_t count,
                                         const std::string& detail, std::optional<std::int64_t> device_time_us,
                                         std::int64_t wall_ns) const {
  nlohmann::json event;
  if (device_time_us) event["timestamp"] = static_cast<double>(*device_time_us) / 1e6;
  event["link"] = link_names_.at(link);
  event["kind"] = kind;
  event["count"] = count;
  event["detail"] = detail;
  event["wall_ns"] = wall_ns;
  return event.dump();
}

}  // namespace imubridge::daemon
