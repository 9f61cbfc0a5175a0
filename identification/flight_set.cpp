#include "identification/flight_set.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace imubridge::estimator {

ImuSeries cut(const ImuSeries& series, const TimeWindow& window) {
  const auto first =
      static_cast<std::size_t>(std::lower_bound(series.t.begin(), series.t.end(), window.start) - series.t.begin());
  const auto last =
      static_cast<std::size_t>(std::lower_bound(series.t.begin(), series.t.end(), window.end) - series.t.begin());
  ImuSeries out;
  const auto take = [first, last](const auto& v) { return std::vector(v.begin() + first, v.begin() + last); };
  out.t = take(series.t);
  out.gyro = take(series.gyro);
  out.accel = take(series.accel);
  if (series.reference)
    out.reference = ReferenceSeries{take(series.reference->velocity_ned), take(series.reference->attitude)};
  out.landed = series.landed;  // on the same clock
  return out;
}

FlightSet join_flights(std::span<const ImuSeries> flights, std::size_t align) {
  if (flights.empty()) throw std::invalid_argument("no flights to join");
  align = std::max<std::size_t>(align, 1);
  const bool reference = std::all_of(flights.begin(), flights.end(), [](const ImuSeries& f) { return f.reference; });
  FlightSet out;
  if (reference) out.series.reference.emplace();
  double next_start = 0.0;
  for (std::size_t i = 0; i < flights.size(); ++i) {
    const ImuSeries& f = flights[i];
    require_valid(f);
    const std::size_t n = f.size() / align * align;
    if (n < 2) throw std::invalid_argument("flight " + std::to_string(i + 1) + " of the set has too few samples");
    const double shift = next_start - f.t.front();
    for (std::size_t k = 0; k < n; ++k) {
      out.series.t.push_back(f.t[k] + shift);
      out.series.gyro.push_back(f.gyro[k]);
      out.series.accel.push_back(f.accel[k]);
      if (reference) {
        out.series.reference->velocity_ned.push_back(f.reference->velocity_ned[k]);
        out.series.reference->attitude.push_back(f.reference->attitude[k]);
      }
    }
    // The last sample's period, as data_span() counts it: the flight ends one period after its last sample.
    const double end = f.t[n - 1] + (f.t[n - 1] - f.t[n - 2]) + shift;
    out.placed.push_back({next_start, end});
    for (const TimeWindow& w : f.landed) {  // moved with the flight, and kept to its place
      const TimeWindow moved{std::max(w.start + shift, next_start), std::min(w.end + shift, end)};
      if (moved.start < moved.end) out.series.landed.push_back(moved);
    }
    out.shift.push_back(shift);
    out.flown_seconds += end - next_start;
    next_start = end + kFlightGapSeconds;
  }
  return out;
}

}  // namespace imubridge::estimator
