#pragma once
// The IMU: where it sits on the body, what a perfect sensor there reads (docs/model.md), and the sensor's errors.
#include <Eigen/Core>
#include <cstdint>

#include "protocol/calibration.hpp"
#include "sim/flight.hpp"
#include "sim/random.hpp"

namespace imubridge::sim {

struct ImuPose {
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();            // r: from the mass centre, body axes
  Eigen::Matrix3d sensor_from_body = Eigen::Matrix3d::Identity();  // R_sb

  // The paper's placement (r, beta, alpha): at r * (cos beta, 0, -sin beta), sensor x axis (cos a, 0, -sin a).
  static ImuPose paper(double r_m, double beta_rad, double alpha_rad);
};

// Defaults: ADXL327 (250 ug/sqrt(Hz)) and ITG3200 (0.03 deg/s/sqrt(Hz)) noise, no other error.
struct ImuErrors {
  Eigen::Vector3d accel_bias = Eigen::Vector3d::Zero();  // m/s^2, sensor axes
  // m/s^2 per s, sensor axes: the bias drifting from accel_bias at t = 0, as a MEMS accelerometer warming up does.
  Eigen::Vector3d accel_bias_drift = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();   // rad/s
  // Reading = M * specific force: diagonal 1 + scale error, off-diagonal cross-axis coupling.
  Eigen::Matrix3d accel_scale_cross = Eigen::Matrix3d::Identity();
  double accel_noise_density = 250e-6 * kGravity;  // m/s^2/sqrt(Hz)
  double gyro_noise_density = 5.2e-4;              // rad/s/sqrt(Hz)
  double mag_noise_ut = 0.05;                      // per sample
  double time_offset_s = 0.0;                      // > 0: the accelerometer's samples lag the gyro's
  double vibration_hz = 0.0;                       // motor vibration added on every accelerometer axis
  double vibration_amplitude = 0.0;                // m/s^2
  double accel_nonlinearity = 0.0;                 // 1/(m/s^2): each axis also reads this times its force squared
};

struct ImuConfig {
  ImuPose pose;
  double rate_hz = 200.0;
  ImuErrors errors;
  Eigen::Vector3d earth_field_ned_ut{28.8, 2.5, 37.0};  // a mid-latitude field (about Tehran's)
  double temperature_c = 25.0;
  double temperature_drift_c_per_s = 0.005;
  // Quantisation and range: readings become the board's counts and are decoded back.
  protocol::Calibration calibration = protocol::Calibration::reference_board();
};

// One reading in sensor axes, SI: specific force m/s^2, rate rad/s, field microtesla.
struct ImuReading {
  Eigen::Vector3d accel = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();
  Eigen::Vector3d mag = Eigen::Vector3d::Zero();
  double temperature_c = 0.0;
};

// A perfect sensor at `imu.pose`: f = R_sb (f_cm + w_dot x r + w x (w x r)), gyro R_sb w, the Earth's field.
ImuReading ideal_reading(const ImuConfig& imu, const TrueState& truth);

// The sensor's errors, applied to ideal readings one sample at a time (noise needs the sample order).
class ImuErrorModel {
 public:
  ImuErrorModel(const ImuErrors& errors, double rate_hz, Rng rng);

  // `ideal` is the reading at sample time t; `lagged_accel` the ideal specific force at t - time_offset_s.
  ImuReading apply(const ImuReading& ideal, const Eigen::Vector3d& lagged_accel, double t);

 private:
  Eigen::Vector3d noise(double sigma);

  ImuErrors errors_;
  double accel_sigma_, gyro_sigma_;  // per sample: density * sqrt(Nyquist bandwidth)
  Rng rng_;
};

}  // namespace imubridge::sim
