#pragma once
// Physical constants shared by the estimator's models (docs/model.md).
#include <numbers>

namespace imubridge::estimator {

inline constexpr double kGravity = 9.80665;  // m/s^2, standard gravity; NED world, so gravity is +kGravity along Z
inline constexpr double kPi = std::numbers::pi;

}  // namespace imubridge::estimator
