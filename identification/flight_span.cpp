#include "identification/flight_span.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

namespace imubridge::estimator {
namespace {

struct Block {
  double start = 0.0, end = 0.0, level = 0.0;
};

double percentile(std::vector<double> values, double fraction) {
  const auto at = static_cast<std::size_t>(fraction * static_cast<double>(values.size() - 1));
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(at), values.end());
  return values[at];
}

}  // namespace

std::optional<FlightSpan> detect_flight(const ImuSeries& s) {
  std::vector<Block> blocks;
  double sum = 0.0;
  std::size_t count = 0, first = 0;
  for (std::size_t k = 1; k < s.size(); ++k) {
    sum += (s.accel[k] - s.accel[k - 1]).squaredNorm();
    ++count;
    const bool last = k + 1 == s.size();
    if (s.t[k] - s.t[first] >= kFlightBlockSeconds || last) {
      if (s.t[k] - s.t[first] >= 0.5 * kFlightBlockSeconds)
        blocks.push_back({s.t[first], s.t[k], std::sqrt(sum / static_cast<double>(count))});
      sum = 0.0, count = 0, first = k;
    }
  }
  if (blocks.size() < 2) return std::nullopt;
  std::vector<double> levels;
  for (const Block& b : blocks) levels.push_back(b.level);
  FlightSpan out;
  out.quiet_level = percentile(levels, 0.05);
  out.flying_level = percentile(levels, 0.95);
  if (!(out.flying_level > kMinFlightContrast * out.quiet_level)) return std::nullopt;
  // Rotors idling on the ground turn at a fraction of hover speed and vibrate several times less than in flight:
  // a third of the flying level keeps a spin-up before take-off out, the geometric mean keeps the rest out.
  const double threshold = std::max(std::sqrt(out.quiet_level * out.flying_level), out.flying_level / 3.0);
  // The flight is the longest run of vibrating blocks: a knock while the vehicle is carried is not a flight.
  std::size_t best_first = 0, best_count = 0;
  for (std::size_t i = 0; i < blocks.size();) {
    if (!(blocks[i].level > threshold)) {
      ++i;
      continue;
    }
    std::size_t j = i;
    while (j < blocks.size() && blocks[j].level > threshold) ++j;
    if (j - i > best_count) best_first = i, best_count = j - i;
    i = j;
  }
  out.window = {blocks[best_first].start, blocks[best_first + best_count - 1].end};
  char text[200];
  std::snprintf(text, sizeof text,
                "in flight %.3f:%.3f s (rotor vibration: accelerometer change %.3g m/s^2 RMS flying, %.3g at rest)",
                out.window.start, out.window.end, out.flying_level, out.quiet_level);
  out.description = text;
  return out;
}

std::optional<FlightSpan> flight_from_land_detector(std::span<const TimeWindow> airborne, const TimeWindow& data) {
  std::optional<FlightSpan> out;
  for (const TimeWindow& w : airborne) {
    const TimeWindow clipped{std::max(w.start, data.start), std::min(w.end, data.end)};
    if (!(clipped.end > clipped.start)) continue;
    if (out && clipped.end - clipped.start <= out->window.end - out->window.start) continue;
    out.emplace();
    out->window = clipped;
  }
  if (!out) return out;
  char text[200];
  std::snprintf(text, sizeof text, "in flight %.3f:%.3f s (the log's land detector: its takeoff and landing%s)",
                out->window.start, out->window.end, airborne.size() > 1 ? ", the longest of its flights" : "");
  out->description = text;
  return out;
}

std::optional<double> share_in_flight(const TimeWindow& window, const TimeWindow& flight, const TimeWindow& data) {
  const double start = std::max(window.start, data.start), end = std::min(window.end, data.end);
  if (!(end > start)) return std::nullopt;
  const double inside = std::max(0.0, std::min(end, flight.end) - std::max(start, flight.start));
  return inside / (end - start);
}

}  // namespace imubridge::estimator
