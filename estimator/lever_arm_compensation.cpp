#include "estimator/lever_arm_compensation.hpp"

#include <ceres/rotation.h>

#include <Eigen/LU>  // inverse()

namespace imubridge::estimator {

LeverArmCompensator::LeverArmCompensator(const FullModelParams& params)
    : lever_arm_(params.lever_arm), accel_bias_(params.accel_bias) {
  // Ceres's column-major default matches Eigen's storage; the same Rodrigues formula as predict_specific_force.
  ceres::AngleAxisToRotationMatrix(params.mounting.data(), imu_to_body_.data());
  // Without scale or cross-axis errors keep R_bs itself, so such a model compensates exactly as before.
  accel_to_body_ = imu_to_body_;
  if (params.accel_scale != Eigen::Vector3d::Zero() || params.accel_cross != Eigen::Matrix3d::Zero()) {
    accel_to_body_ = imu_to_body_ * sensor_matrix(params).inverse();
  }
}

Eigen::Vector3d LeverArmCompensator::compensate(const Eigen::Vector3d& accel, const Eigen::Vector3d& gyro,
                                                const Eigen::Vector3d& gyro_rate) const {
  const Eigen::Vector3d w = imu_to_body_ * gyro;
  const Eigen::Vector3d w_dot = imu_to_body_ * gyro_rate;
  return accel_to_body_ * (accel - accel_bias_) - w_dot.cross(lever_arm_) - w.cross(w.cross(lever_arm_));
}

}  // namespace imubridge::estimator
