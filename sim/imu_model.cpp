#include "sim/imu_model.hpp"

#include <cmath>
#include <numbers>

namespace imubridge::sim {

using Eigen::Vector3d;

ImuPose ImuPose::paper(double r_m, double beta_rad, double alpha_rad) {
  ImuPose pose;
  pose.position_m = r_m * Vector3d(std::cos(beta_rad), 0.0, -std::sin(beta_rad));
  // R_y(alpha)^T: its first row, the sensor x axis in body axes, is (cos a, 0, -sin a).
  pose.sensor_from_body = Eigen::AngleAxisd(alpha_rad, Vector3d::UnitY()).toRotationMatrix().transpose();
  return pose;
}

ImuReading ideal_reading(const ImuConfig& imu, const TrueState& truth) {
  const Eigen::Matrix3d& r_sb = imu.pose.sensor_from_body;
  const Vector3d& r = imu.pose.position_m;
  const Vector3d& w = truth.omega;
  const Vector3d lever_arm = truth.omega_dot.cross(r) + w.cross(w.cross(r));
  return {r_sb * (truth.specific_force + lever_arm), r_sb * w,
          r_sb * (truth.attitude.conjugate() * imu.earth_field_ned_ut),
          imu.temperature_c + imu.temperature_drift_c_per_s * truth.time_s};
}

ImuErrorModel::ImuErrorModel(const ImuErrors& errors, double rate_hz, Rng rng)
    : errors_(errors),
      accel_sigma_(errors.accel_noise_density * std::sqrt(rate_hz / 2)),
      gyro_sigma_(errors.gyro_noise_density * std::sqrt(rate_hz / 2)),
      rng_(rng) {}

Vector3d ImuErrorModel::noise(double sigma) {
  // Drawn even when sigma is 0 so that switching one noise off leaves the others' sequences unchanged.
  // Separate declarators fix the draw order (function arguments would leave it unspecified).
  const double x = rng_.normal(), y = rng_.normal(), z = rng_.normal();
  return sigma * Vector3d(x, y, z);
}

ImuReading ImuErrorModel::apply(const ImuReading& ideal, const Vector3d& lagged_accel, double t) {
  const double vibration = errors_.vibration_amplitude * std::sin(2 * std::numbers::pi * errors_.vibration_hz * t);
  ImuReading out = ideal;
  out.accel = errors_.accel_scale_cross * lagged_accel + errors_.accel_nonlinearity * lagged_accel.cwiseAbs2() +
              errors_.accel_bias + errors_.accel_bias_drift * t + Vector3d::Constant(vibration) + noise(accel_sigma_);
  out.gyro = ideal.gyro + errors_.gyro_bias + noise(gyro_sigma_);
  out.mag = ideal.mag + noise(errors_.mag_noise_ut);
  return out;
}

}  // namespace imubridge::sim
