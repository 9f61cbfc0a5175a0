#include "estimator/full_model.hpp"

#include <Eigen/LU>  // determinant()
#include <cmath>

namespace imubridge::estimator {

std::optional<std::string> validate(const FullModelParams& p) {
  if (!p.lever_arm.allFinite() || !p.mounting.allFinite() || !p.drag_linear.allFinite() ||
      !p.drag_quadratic.allFinite() || !p.accel_bias.allFinite() || !p.accel_scale.allFinite() ||
      !p.accel_cross.allFinite() || !p.gyro_bias.allFinite() || !std::isfinite(p.time_offset) ||
      !p.wind.allFinite() || !std::isfinite(p.wind_heading))
    return "non-finite parameter";
  // Negative drag would make the law non-monotonic: no unique velocity for a measured drag.
  if ((p.drag_linear.array() < 0.0).any() || (p.drag_quadratic.array() < 0.0).any()) return "negative drag coefficient";
  // A scale of -1 or below reads nothing, or the force reversed, on that axis: not a sensor error to undo.
  if (!(p.accel_scale.array() > -1.0).all()) return "accel_scale must be greater than -1";
  // The diagonal is accel_scale's; a second place for it would make the pair ambiguous.
  if (p.accel_cross.diagonal() != Eigen::Vector3d::Zero()) return "accel_cross must have a zero diagonal";
  // The estimator inverts I + diag(scale) + cross; a non-positive determinant maps some force to zero or mirrors
  // the axes.
  const Eigen::Matrix3d sensor = sensor_matrix(p);
  if (!(sensor.determinant() > 0.0)) return "accel_scale and accel_cross make a singular accelerometer";
  // diagnose's bound on tau: beyond it the streams are not one sensor's; the live aligner's ring is sized for it.
  if (std::abs(p.time_offset) > 0.25) return "|time_offset| must be at most 0.25 s";
  return std::nullopt;
}

}  // namespace imubridge::estimator
