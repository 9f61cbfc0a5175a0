#pragma once
// Several flights of one vehicle as one series, for the fits that take a series (identify, the filter error method):
// a calibration fitted over several flights averages out what one flight alone cannot tell from the vehicle (its
// wind, its offsets, the few manoeuvres it flew). The flights follow one another with a long gap between them,
// which the drag-velocity filter treats as a pause (it restarts its differentiator and its variance grows over the
// gap, docs/estimator.md), so no flight's state carries into the next.
#include <cstddef>
#include <span>
#include <vector>

#include "estimator/imu_series.hpp"
#include "estimator/params.hpp"

namespace imubridge::estimator {

// Long enough that the filter's velocity and tilt variances grow past any flight's (its process noise over the gap).
inline constexpr double kFlightGapSeconds = 1000.0;

struct FlightSet {
  ImuSeries series;                // the flights one after another; a reference only when every flight has one
  std::vector<TimeWindow> placed;  // where each flight lies in `series`' time
  std::vector<double> shift;       // each flight's time in `series` minus its own time, s
  double flown_seconds = 0.0;      // the flights' own lengths summed (the gaps left out)
};

// Each flight keeps its samples' spacing; `align` > 1 keeps a whole number of `align`-sample blocks of each (the
// filter error method averages blocks by index, and a block must not straddle two flights). Throws
// std::invalid_argument for no flights, an invalid one, or one shorter than a block.
FlightSet join_flights(std::span<const ImuSeries> flights, std::size_t align = 1);

// The samples of `series` with window.start <= t < window.end, as a series of their own (reference included).
ImuSeries cut(const ImuSeries& series, const TimeWindow& window);

}  // namespace imubridge::estimator
