#pragma once
// Lever-arm compensation: the 3-D model (estimator/full_model.hpp) solved for the specific force at the mass centre,
//   f_cm = R_bs S^-1 (m - b_a) - w_dot x r - w x (w x r),   w = R_bs w_imu   (body axes),
// S = I + diag(accel_scale) + accel_cross the accelerometer's scale and cross-axis errors, m its reading. The gyro
// given is taken as already corrected (the caller subtracts gyro_bias before differentiating it).
// Its x and y rows are the drag the paper's section VIII reads (the thrust has no horizontal component in body
// axes); its z row is -T, the thrust specific force the 3-D model takes as input.
#include <Eigen/Core>
#include <Eigen/Geometry>

#include "estimator/full_model.hpp"

namespace imubridge::estimator {

class LeverArmCompensator {
 public:
  explicit LeverArmCompensator(const FullModelParams& params);

  // accel, gyro, gyro_rate in IMU axes; returns f_cm in body axes.
  Eigen::Vector3d compensate(const Eigen::Vector3d& accel, const Eigen::Vector3d& gyro,
                             const Eigen::Vector3d& gyro_rate) const;
  // IMU axes -> body axes.
  Eigen::Vector3d to_body(const Eigen::Vector3d& v_imu) const { return imu_to_body_ * v_imu; }

 private:
  Eigen::Matrix3d imu_to_body_;    // R_bs, computed once: the per-sample path is three 3x3 products and two crosses
  Eigen::Matrix3d accel_to_body_;  // R_bs S^-1, computed once; exactly R_bs when S = I
  Eigen::Vector3d lever_arm_;
  Eigen::Vector3d accel_bias_;
};

}  // namespace imubridge::estimator
