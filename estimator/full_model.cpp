#include "estimator/full_model.hpp"

namespace imubridge::estimator {

std::optional<std::string> validate(const FullModelParams& p) {
  if (!p.lever_arm.allFinite() || !p.mounting.allFinite() || !p.drag_linear.allFinite() ||
      !p.drag_quadratic.allFinite() || !p.accel_bias.allFinite())
    return "non-finite parameter";
  // Negative drag would make the law non-monotonic: no unique velocity for a measured drag.
  if ((p.drag_linear.array() < 0.0).any() || (p.drag_quadratic.array() < 0.0).any()) return "negative drag coefficient";
  return std::nullopt;
}

}  // namespace imubridge::estimator
