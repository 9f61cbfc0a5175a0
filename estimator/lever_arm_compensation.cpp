#include "estimator/lever_arm_compensation.hpp"

#include <ceres/rotation.h>

namespace imubridge::estimator {

LeverArmCompensator::LeverArmCompensator(const FullModelParams& params)
    : lever_arm_(params.lever_arm), accel_bias_(params.accel_bias) {
  // Ceres's column-major default matches Eigen's storage; the same Rodrigues formula as predict_specific_force.
  ceres::AngleAxisToRotationMatrix(params.mounting.data(), imu_to_body_.data());
}

Eigen::Vector3d LeverArmCompensator::compensate(const Eigen::Vector3d& accel, const Eigen::Vector3d& gyro,
                                                const Eigen::Vector3d& gyro_rate) const {
  const Eigen::Vector3d w = imu_to_body_ * gyro;
  const Eigen::Vector3d w_dot = imu_to_body_ * gyro_rate;
  return imu_to_body_ * (accel - accel_bias_) - w_dot.cross(lever_arm_) - w.cross(w.cross(lever_arm_));
}

}  // namespace imubridge::estimator
