#pragma once
// Named scenarios. A scenario is fully determined by (name, seed, duration, effects).
//   paper  - the paper's experiment (section VII): IMU far from the mass centre with the identified
//            (r, beta, alpha, mu), agile pitch and some roll manoeuvres, 60 s at 200 Hz.
//   center - the same flight with the IMU at the mass centre, axes aligned (the paper's section VIII).
//   hover  - no manoeuvres, IMU at the mass centre, the paper's drag, 10 s.
//   agile  - the paper's IMU pose and drag with tilts up to 0.6 rad (the paper's: 0.35), half of them in roll: the
//            thrust varies by up to a fifth, and roll and pitch both turn the sensor.
//   climb  - the agile flight (same roll and pitch plan) with climbs and descents of 0.3-1 m at up to g/2: the thrust
//            varies by tens of per cent.
//   survey - the paper's flight with turns of the heading between legs of several seconds: a constant wind turns
//            through the body axes, where no sensor tilt or bias follows it.
#include <cstdint>
#include <numbers>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "sim/simulator.hpp"

namespace imubridge::sim {

// The paper's identified parameters (r, beta, alpha, mu) = (0.179 m, 85.12 deg, -0.3 deg, 0.0386 1/m).
inline constexpr double kPaperR = 0.179;
inline constexpr double kPaperBeta = 85.12 * std::numbers::pi / 180;
inline constexpr double kPaperAlpha = -0.3 * std::numbers::pi / 180;
inline constexpr double kPaperMu = 0.0386;

std::span<const std::string_view> scenario_names();

// The longest flight a scenario flies: a day. The simulator streams, so memory does not limit it; the time to
// compute it does (a day's flight takes minutes).
inline constexpr double kMaxDurationS = 24 * 3600.0;

// Throws std::invalid_argument for an unknown name (listing the valid ones), a duration that is not positive and
// at most kMaxDurationS, or a bad effect (see effects.hpp). Without a duration the scenario's own is used.
SimConfig make_scenario(std::string_view name, std::uint64_t seed, std::optional<double> duration_s = std::nullopt,
                        std::span<const std::string> effects = {});

}  // namespace imubridge::sim
