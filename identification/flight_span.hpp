#pragma once
// The part of a recording where the vehicle flies, from the IMU alone: spinning rotors shake the airframe, and an
// accelerometer on it reads that vibration tens of times above its noise at rest (docs/identification.md,
// "Windows"). Users' recordings start and end on the ground, by hand, or on a bench; a model is identified and judged
// on the flight.
#include <optional>
#include <span>
#include <string>

#include "estimator/imu_series.hpp"
#include "estimator/params.hpp"

namespace imubridge::estimator {

struct FlightSpan {
  TimeWindow window;          // s: from the first to the end of the last vibrating block
  double quiet_level = 0.0;   // m/s^2: the quietest blocks' high-frequency accelerometer level (5th percentile)
  double flying_level = 0.0;  // m/s^2: the loudest blocks' (95th percentile)
  std::string description;    // one line for people
};

// Blocks of kFlightBlockSeconds; a block flies when its level (RMS of the sample-to-sample change of the specific
// force: the vibration band, whatever the manoeuvres) is above both the geometric mean of the quiet and flying levels
// and a third of the flying level; the flight is the longest run of such blocks. nullopt when the recording shows no
// quiet part to tell apart (the levels within kMinFlightContrast of each other: airborne throughout, or never) or is
// shorter than two blocks.
inline constexpr double kFlightBlockSeconds = 0.5;
inline constexpr double kMinFlightContrast = 4.0;
std::optional<FlightSpan> detect_flight(const ImuSeries& series);

// The flight by the log's own land detector (`airborne`: its takeoff-to-landing intervals, an open end infinite):
// the longest one clipped to `data`, said as such; nullopt when none lies in the data. A land detector knows when
// the vehicle left the ground; the vibration only suggests it.
std::optional<FlightSpan> flight_from_land_detector(std::span<const TimeWindow> airborne, const TimeWindow& data);

// The share of `window`, clipped to the data's span, that lies in `flight` (0 to 1); nullopt when the clipped window
// is empty. A fit window mostly on the ground identifies nothing a flight model has.
std::optional<double> share_in_flight(const TimeWindow& window, const TimeWindow& flight, const TimeWindow& data);

}  // namespace imubridge::estimator
