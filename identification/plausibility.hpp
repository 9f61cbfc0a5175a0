#pragma once
// What a multirotor's identified model may physically be (docs/identification.md, "Plausibility"). A fit can buy a
// lower residual with values no airframe has: a lever arm longer than the vehicle, a gale inside a hall, a sensor
// whose scale is off by a third. `identify` flags such values; `diagnose` refuses the candidate that needs them.
// One table, here; every limit can be overridden on the command line (--limit NAME=VALUE).
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "estimator/full_model.hpp"

namespace imubridge::estimator {

struct PlausibilityLimits {
  // |lever arm|, m: the IMU sits on the airframe; 0.5 m is half the diagonal of a large (1 m) multirotor.
  double lever_arm = 0.5;
  // |wind|, m/s: beyond a strong breeze (Beaufort 8 starts at 17 m/s) small multirotors do not fly.
  double wind = 20.0;
  // |accel_scale| per axis: MEMS accelerometers are specified to a few percent of sensitivity error.
  double accel_scale = 0.10;
  // |accel_cross| per pair of axes: datasheet cross-axis sensitivity is 1-2 %, mounting adds little more.
  double accel_cross = 0.05;
  // |gyro bias| per axis, rad/s (5.7 deg/s): far beyond any MEMS gyro's zero-rate offset after start-up.
  double gyro_bias = 0.1;
  // |accel bias| per axis, m/s^2 (0.1 g): beyond MEMS accelerometers' zero-g offsets (typically 0.02-0.06 g).
  double accel_bias = 1.0;
  // |time offset| between accelerometer and gyro, s: one device's filters and buses delay by milliseconds to tens.
  double time_offset = 0.1;
  // Drag at kBriskSpeed beyond g: holding that speed would need a tilt past 45 degrees, where multirotors do not cruise
  // (their attitude limits are 30-45 degrees). k = g / kBriskSpeed (1/s) and mu = g / kBriskSpeed^2 (1/m) alone each
  // give g there.
  double drag_linear = 2.0;     // k per axis, 1/s
  double drag_quadratic = 0.4;  // mu per axis, 1/m
};

// One limit the values exceed, in a line a person reads: "wind 31.2 m/s exceeds its limit 20 m/s (--limit wind=...)".
struct Implausibility {
  std::string limit;  // the limit's name, as --limit takes it
  double value = 0.0;
  double bound = 0.0;
  std::string message;
  // A limit on one axis's value (a drag coefficient, a scale, a bias, a coupling), not on a vector's length or a
  // scalar: the axis alone can be held at zero (diagnose does, for an axis the flight hardly excites).
  bool per_axis = false;
};

// Every limit the model's values exceed (an empty list: plausible).
std::vector<Implausibility> check_plausibility(const FullModelParams& params, const PlausibilityLimits& limits = {});

// A drag too small to see: at kBriskSpeed it gives less than kDragVisible of specific force, below what an
// accelerometer reads through its noise, so the velocity inverted from it is noise. One line per such horizontal axis
// ("no usable drag on x: ..."); empty when both axes have one. A fit on eq. (12)'s drifting velocity ends here.
inline constexpr double kBriskSpeed = 5.0;   // m/s
inline constexpr double kDragVisible = 0.1;  // m/s^2, the drag-velocity filter's default accelerometer noise
std::vector<std::string> negligible_drag(const FullModelParams& params);

// The limits' names and values, in the table's order (for the docs).
std::vector<std::pair<std::string, double>> limit_table(const PlausibilityLimits& limits = {});
// The same for --limit's help, each with its unit and default: "lever_arm (m, default 0.5), wind (m/s, ...), ...".
std::string limit_help(const PlausibilityLimits& limits = {});

// Applies "NAME=VALUE" (VALUE > 0) to `limits`; throws std::invalid_argument naming the valid limits otherwise.
void override_limit(PlausibilityLimits& limits, std::string_view assignment);

}  // namespace imubridge::estimator
