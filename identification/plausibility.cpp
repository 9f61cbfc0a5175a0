#include "identification/plausibility.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace imubridge::estimator {
namespace {

// The table: name, the member it sets, and the unit printed beside values.
struct LimitEntry {
  const char* name;
  double PlausibilityLimits::*member;
  const char* unit;
};
constexpr LimitEntry kLimits[] = {
    {"lever_arm", &PlausibilityLimits::lever_arm, "m"},
    {"wind", &PlausibilityLimits::wind, "m/s"},
    {"accel_scale", &PlausibilityLimits::accel_scale, ""},
    {"accel_cross", &PlausibilityLimits::accel_cross, ""},
    {"gyro_bias", &PlausibilityLimits::gyro_bias, "rad/s"},
    {"accel_bias", &PlausibilityLimits::accel_bias, "m/s^2"},
    {"time_offset", &PlausibilityLimits::time_offset, "s"},
    {"drag_linear", &PlausibilityLimits::drag_linear, "1/s"},
    {"drag_quadratic", &PlausibilityLimits::drag_quadratic, "1/m"},
};

const LimitEntry& entry(const char* name) {
  for (const LimitEntry& e : kLimits) {
    if (std::string_view(e.name) == name) return e;
  }
  throw std::logic_error("no plausibility limit " + std::string(name));
}

void check(std::vector<Implausibility>& out, const PlausibilityLimits& limits, const char* name, const char* what,
           double value, bool per_axis = true) {
  const LimitEntry& e = entry(name);
  const double bound = limits.*(e.member);
  if (!(std::abs(value) > bound)) return;
  char text[200];
  std::snprintf(text, sizeof text, "%s %.4g %s exceeds its plausible limit %g %s (--limit %s=VALUE to change it)", what,
                value, e.unit, bound, e.unit, name);
  out.push_back({name, value, bound, text, per_axis});
}

const char* const kAxis[] = {"x", "y", "z"};

}  // namespace

std::vector<std::string> negligible_drag(const FullModelParams& p) {
  std::vector<std::string> out;
  for (int axis = 0; axis < 2; ++axis) {
    const double k = p.drag_linear[axis], mu = p.drag_quadratic[axis];
    const double force = k * kBriskSpeed + mu * kBriskSpeed * kBriskSpeed;
    if (force >= kDragVisible) continue;
    char line[320];
    std::snprintf(line, sizeof line,
                  "no usable drag on %c: k = %.3g 1/s and mu = %.3g 1/m give %.3g m/s^2 at %g m/s, below the %g m/s^2 "
                  "an accelerometer reads through its noise: the estimator has no usable velocity to give on that axis",
                  "xy"[axis], k, mu, force, kBriskSpeed, kDragVisible);
    out.emplace_back(line);
  }
  return out;
}

std::vector<Implausibility> check_plausibility(const FullModelParams& p, const PlausibilityLimits& limits) {
  std::vector<Implausibility> out;
  check(out, limits, "lever_arm", "lever arm |r|", p.lever_arm.norm(), false);
  check(out, limits, "wind", "wind speed", p.wind.norm(), false);
  for (int i = 0; i < 3; ++i) {
    const std::string axis = kAxis[i];
    check(out, limits, "accel_scale", ("accelerometer scale error " + axis).c_str(), p.accel_scale[i]);
    check(out, limits, "gyro_bias", ("gyro bias " + axis).c_str(), p.gyro_bias[i]);
    check(out, limits, "accel_bias", ("accelerometer bias " + axis).c_str(), p.accel_bias[i]);
    for (int j = 0; j < 3; ++j) {
      if (i == j) continue;
      check(out, limits, "accel_cross", ("cross-axis coupling " + axis + kAxis[j]).c_str(), p.accel_cross(i, j));
    }
  }
  check(out, limits, "time_offset", "accelerometer-gyro time offset", p.time_offset, false);
  for (int i = 0; i < 2; ++i) {
    const std::string axis = kAxis[i];
    check(out, limits, "drag_linear", ("linear drag k." + axis).c_str(), p.drag_linear[i]);
    check(out, limits, "drag_quadratic", ("quadratic drag mu." + axis).c_str(), p.drag_quadratic[i]);
  }
  return out;
}

std::vector<std::pair<std::string, double>> limit_table(const PlausibilityLimits& limits) {
  std::vector<std::pair<std::string, double>> out;
  for (const LimitEntry& e : kLimits) out.emplace_back(e.name, limits.*(e.member));
  return out;
}

std::string limit_help(const PlausibilityLimits& limits) {
  std::string out;
  for (const LimitEntry& e : kLimits) {
    char value[32];
    std::snprintf(value, sizeof value, "%g", limits.*(e.member));
    out += std::string(out.empty() ? "" : ", ") + e.name + " (" + (*e.unit ? std::string(e.unit) + ", " : "") +
           "default " + value + ")";
  }
  return out;
}

void override_limit(PlausibilityLimits& limits, std::string_view assignment) {
  std::string valid;
  for (const LimitEntry& e : kLimits) valid += std::string(valid.empty() ? "" : ", ") + e.name;
  const std::size_t eq = assignment.find('=');
  const std::string_view name = assignment.substr(0, eq == std::string_view::npos ? assignment.size() : eq);
  for (const LimitEntry& e : kLimits) {
    if (name != e.name) continue;
    double value = 0.0;
    const std::string_view text = eq == std::string_view::npos ? std::string_view() : assignment.substr(eq + 1);
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (eq == std::string_view::npos || error != std::errc() || end != text.data() + text.size() ||
        !std::isfinite(value) || !(value > 0.0))
      throw std::invalid_argument("bad --limit \"" + std::string(assignment) + "\": expected " + e.name +
                                  "=VALUE with VALUE > 0");
    limits.*(e.member) = value;
    return;
  }
  throw std::invalid_argument("unknown plausibility limit \"" + std::string(name) + "\" (valid: " + valid + ")");
}

}  // namespace imubridge::estimator
