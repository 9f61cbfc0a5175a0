#include "sim/scenario.hpp"

#include <array>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

#include "sim/effects.hpp"

namespace imubridge::sim {

namespace {

constexpr std::array<std::string_view, 6> kNames{"paper", "center", "hover", "agile", "climb", "survey"};

}  // namespace

std::span<const std::string_view> scenario_names() { return kNames; }

SimConfig make_scenario(std::string_view name, std::uint64_t seed, std::optional<double> duration_s,
                        std::span<const std::string> effects) {
  SimConfig config;
  config.seed = seed;
  config.flight.air.quadratic_drag_per_m = kPaperMu;
  if (name == "paper") {
    config.imu.pose = ImuPose::paper(kPaperR, kPaperBeta, kPaperAlpha);
  } else if (name == "center") {
    // Defaults already: IMU at the mass centre, axes aligned.
  } else if (name == "agile" || name == "climb") {
    // Tilts up to twice the paper's, as often in roll as in pitch: the altitude hold's thrust g / (cos phi cos theta)
    // then varies by up to a fifth, and rolling with the sensor tilted separates the lever arm's z from eq. (14).
    config.imu.pose = ImuPose::paper(kPaperR, kPaperBeta, kPaperAlpha);
    config.flight.manoeuvres.amplitude_max_rad = 0.6;
    config.flight.manoeuvres.roll_share = 0.5;
    // Climbs and descents on top, as an identification flight flies them: the thrust varies by tens of per cent.
    config.flight.vertical.enabled = name == "climb";
  } else if (name == "survey") {
    // The paper's pose, drag and manoeuvres, and the heading turned between legs as a survey flight turns it: a
    // constant wind then turns through the body axes, which tells it apart from a sensor tilt or bias (not, from the
    // IMU alone, from a steady ground velocity: docs/effects.md).
    config.imu.pose = ImuPose::paper(kPaperR, kPaperBeta, kPaperAlpha);
    config.flight.turns.enabled = true;
  } else if (name == "hover") {
    config.flight.manoeuvres.enabled = false;
    config.duration_s = 10.0;
  } else {
    std::string valid;
    for (std::string_view n : kNames) valid += " " + std::string(n);
    throw std::invalid_argument("unknown scenario \"" + std::string(name) + "\"; valid scenarios:" + valid);
  }
  if (duration_s) {
    if (!(*duration_s > 0.0 && *duration_s <= kMaxDurationS)) {
      std::ostringstream message;
      message << "the flight's duration must be more than 0 and at most " << kMaxDurationS << " s (24 h), got "
              << *duration_s << " s";
      throw std::invalid_argument(message.str());
    }
    config.duration_s = *duration_s;
  }
  for (const std::string& effect : effects) apply_effect(config, effect);
  return config;
}

}  // namespace imubridge::sim
