#include "sim/effects.hpp"

#include <Eigen/Geometry>
#include <array>
#include <charconv>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace imubridge::sim {

namespace {

using Eigen::Vector3d;
using Values = std::vector<double>;

// "Per axis or all": one number for every axis, or one each.
Vector3d per_axis(const Values& v) { return v.size() == 1 ? Vector3d::Constant(v[0]) : Vector3d(v[0], v[1], v[2]); }

struct Effect {
  EffectInfo info;
  std::array<std::size_t, 2> counts;  // how many numbers VALUE may have: counts[0] or counts[1]
  double min, max;                    // bounds for each number
  void (*apply)(SimConfig&, const Values&);
};

constexpr std::array kEffects{
    Effect{.info = {"linear_drag", "K", "rotor drag -K*v on the horizontal body air velocity, 1/s"},
           .counts = {1, 1},
           .min = 0,
           .max = 100,
           .apply = [](SimConfig& c, const Values& v) { c.flight.air.linear_drag_per_s = v[0]; }},
    Effect{.info = {"quadratic_drag", "MU", "the paper's drag -MU*|v|*v per horizontal body axis, 1/m"},
           .counts = {1, 1},
           .min = 0,
           .max = 100,
           .apply = [](SimConfig& c, const Values& v) { c.flight.air.quadratic_drag_per_m = v[0]; }},
    Effect{.info = {"wind", "N,E[,D]", "constant air velocity, NED, m/s (drag acts on ground velocity - wind)"},
           .counts = {2, 3},
           .min = -50,
           .max = 50,
           .apply =
               [](SimConfig& c, const Values& v) {
                 c.flight.air.wind_ned = {v[0], v[1], v.size() == 3 ? v[2] : 0};
               }},
    Effect{.info = {"accel_bias", "B|BX,BY,BZ", "added to the accelerometer, sensor axes, m/s^2"},
           .counts = {1, 3},
           .min = -100,
           .max = 100,
           .apply = [](SimConfig& c, const Values& v) { c.imu.errors.accel_bias = per_axis(v); }},
    Effect{.info = {"accel_bias_drift", "R|RX,RY,RZ",
                    "the accelerometer bias drifting from accel_bias at this rate (warming up), sensor axes, m/s^2/s"},
           .counts = {1, 3},
           .min = -1,
           .max = 1,
           .apply = [](SimConfig& c, const Values& v) { c.imu.errors.accel_bias_drift = per_axis(v); }},
    Effect{.info = {"gyro_bias", "B|BX,BY,BZ", "added to the gyro, sensor axes, rad/s"},
           .counts = {1, 3},
           .min = -10,
           .max = 10,
           .apply = [](SimConfig& c, const Values& v) { c.imu.errors.gyro_bias = per_axis(v); }},
    Effect{.info = {"accel_scale", "S|SX,SY,SZ", "accelerometer scale error, fraction (0.01 reads 1% high)"},
           .counts = {1, 3},
           .min = -0.5,
           .max = 0.5,
           .apply = [](SimConfig& c,
                       const Values& v) { c.imu.errors.accel_scale_cross.diagonal() = 1 + per_axis(v).array(); }},
    Effect{.info = {"accel_cross", "C|XY,XZ,YX,YZ,ZX,ZY", "cross-axis coupling: fraction of axis B read on axis A"},
           .counts = {1, 6},
           .min = -0.5,
           .max = 0.5,
           .apply =
               [](SimConfig& c, const Values& v) {
                 Eigen::Matrix3d& m = c.imu.errors.accel_scale_cross;
                 const auto at = [&](std::size_t i) { return v.size() == 1 ? v[0] : v[i]; };
                 m(0, 1) = at(0), m(0, 2) = at(1), m(1, 0) = at(2), m(1, 2) = at(3), m(2, 0) = at(4), m(2, 1) = at(5);
               }},
    Effect{.info = {"time_offset", "TAU", "accelerometer samples lag the gyro's by TAU s (negative: lead)"},
           .counts = {1, 1},
           .min = -1,
           .max = 1,
           .apply = [](SimConfig& c, const Values& v) { c.imu.errors.time_offset_s = v[0]; }},
    Effect{.info = {"vibration", "HZ,AMP", "motor vibration: AMP m/s^2 sinusoid at HZ on every accelerometer axis"},
           .counts = {2, 2},
           .min = 0,
           .max = 1e4,
           .apply =
               [](SimConfig& c, const Values& v) {
                 c.imu.errors.vibration_hz = v[0];
                 c.imu.errors.vibration_amplitude = v[1];
               }},
    Effect{.info = {"accel_nonlinearity", "C", "each accelerometer axis also reads C times its specific force squared, "
                                               "1/(m/s^2)"},
           .counts = {1, 1},
           .min = -1,
           .max = 1,
           .apply = [](SimConfig& c, const Values& v) { c.imu.errors.accel_nonlinearity = v[0]; }},
    Effect{.info = {"imu_tilt", "A", "the sensor turned by A rad about y_b, the paper's alpha (replaces the scenario's)"},
           .counts = {1, 1},
           .min = -3.2,
           .max = 3.2,
           .apply =
               [](SimConfig& c, const Values& v) {
                 c.imu.pose.sensor_from_body =
                     Eigen::AngleAxisd(v[0], Eigen::Vector3d::UnitY()).toRotationMatrix().transpose();
               }},
    Effect{.info = {"accel_noise", "D", "accelerometer white noise density, m/s^2/sqrt(Hz)"},
           .counts = {1, 1},
           .min = 0,
           .max = 10,
           .apply = [](SimConfig& c, const Values& v) { c.imu.errors.accel_noise_density = v[0]; }},
    Effect{.info = {"gyro_noise", "D", "gyro white noise density, rad/s/sqrt(Hz)"},
           .counts = {1, 1},
           .min = 0,
           .max = 10,
           .apply = [](SimConfig& c, const Values& v) { c.imu.errors.gyro_noise_density = v[0]; }},
    Effect{.info = {"reference_delay", "D", "the reference's position and velocity describe the vehicle D s before "
                                            "their stamp (a GNSS receiver's latency; the attitude stays current), s"},
           .counts = {1, 1},
           .min = 0,
           .max = 5,
           .apply = [](SimConfig& c, const Values& v) { c.reference.delay_s = v[0]; }},
    Effect{.info = {"reference_rate", "HZ", "reference poses per second (default: one per IMU sample), Hz"},
           .counts = {1, 1},
           .min = 0.1,
           .max = 10000,
           .apply = [](SimConfig& c, const Values& v) { c.reference.rate_hz = v[0]; }},
    Effect{.info = {"reference_quantum", "Q", "reference velocity rounded to multiples of Q per component, m/s"},
           .counts = {1, 1},
           .min = 0,
           .max = 10,
           .apply = [](SimConfig& c, const Values& v) { c.reference.velocity_quantum = v[0]; }},
};

constexpr std::array<EffectInfo, kEffects.size()> kCatalogue = [] {
  std::array<EffectInfo, kEffects.size()> infos{};
  for (std::size_t i = 0; i < kEffects.size(); ++i) infos[i] = kEffects[i].info;
  return infos;
}();

std::string shortest(double x) {
  std::array<char, 32> buffer{};
  return {buffer.data(), std::to_chars(buffer.data(), buffer.data() + buffer.size(), x).ptr};
}

[[noreturn]] void fail(std::string_view spec, std::string_view problem) {
  std::string message = "bad effect \"" + std::string(spec) + "\": " + std::string(problem) + "; valid effects:";
  for (const auto& e : kEffects) message += " " + std::string(e.info.name) + "=" + std::string(e.info.value);
  throw std::invalid_argument(message);
}

// Comma-separated finite numbers, or nothing if any piece is not one.
std::optional<Values> parse_numbers(std::string_view text) {
  Values values;
  for (;;) {
    const std::size_t comma = text.find(',');
    const std::string_view piece = text.substr(0, comma);
    double x = 0;
    const auto [end, error] = std::from_chars(piece.data(), piece.data() + piece.size(), x);
    if (error != std::errc() || end != piece.data() + piece.size() || !std::isfinite(x)) return std::nullopt;
    values.push_back(x);
    if (comma == std::string_view::npos) return values;
    text.remove_prefix(comma + 1);
  }
}

}  // namespace

std::span<const EffectInfo> effect_catalogue() { return kCatalogue; }

void apply_effect(SimConfig& config, std::string_view spec) {
  const std::size_t equals = spec.find('=');
  if (equals == std::string_view::npos) fail(spec, "expected NAME=VALUE");
  const std::string_view name = spec.substr(0, equals);
  for (const Effect& e : kEffects) {
    if (e.info.name != name) continue;
    const auto values = parse_numbers(spec.substr(equals + 1));
    if (!values || (values->size() != e.counts[0] && values->size() != e.counts[1])) {
      fail(spec, "VALUE must be " + std::string(e.info.value) + " (" + std::string(e.info.meaning) + ")");
    }
    for (double x : *values) {
      if (x < e.min || x > e.max)
        fail(spec, "each number must be in [" + shortest(e.min) + ", " + shortest(e.max) + "]");
    }
    e.apply(config, *values);
    return;
  }
  fail(spec, "unknown name");
}

}  // namespace imubridge::sim
