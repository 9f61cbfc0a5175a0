#pragma once
// The 3-D accelerometer model of docs/model.md:
//   f_imu = R_sb (f_cm + w_dot x r + w x (w x r)) + b_a,   f_cm = (drag_x(v_x), drag_y(v_y), -T),   w = R_bs w_imu
// R_bs = Exp(mounting) turns IMU axes into body axes and R_sb = R_bs^T. The paper's alpha about y_b is
// mounting = (0, alpha, 0): the sensor's x axis is then (cos alpha, 0, -sin alpha) in body axes.
#include <ceres/rotation.h>

#include <Eigen/Core>
#include <Eigen/Geometry>  // cross()
#include <optional>
#include <string>

#include "estimator/drag_law.hpp"

namespace imubridge::estimator {

// The defaults disable compensation: IMU at the mass centre, aligned with the body, no drag, no bias.
struct FullModelParams {
  Eigen::Vector3d lever_arm = Eigen::Vector3d::Zero();       // r: IMU position from the mass centre, body axes, m
  Eigen::Vector3d mounting = Eigen::Vector3d::Zero();        // rotation vector of R_bs (IMU -> body), rad
  Eigen::Vector2d drag_linear = Eigen::Vector2d::Zero();     // k_x, k_y, 1/s
  Eigen::Vector2d drag_quadratic = Eigen::Vector2d::Zero();  // mu_x, mu_y, 1/m
  Eigen::Vector3d accel_bias = Eigen::Vector3d::Zero();      // b_a, IMU axes, m/s^2

  // The effects beyond the rigid body that the live estimator also undoes (docs/effects.md, "Live"). None enters
  // predict_specific_force(): identify fits the five blocks above; diagnose fits these as effects.
  //
  // The accelerometer reads m = (I + diag(accel_scale) + accel_cross) f + accel_bias, in IMU axes.
  Eigen::Vector3d accel_scale = Eigen::Vector3d::Zero();  // relative scale error per IMU axis
  Eigen::Matrix3d accel_cross = Eigen::Matrix3d::Zero();  // (a, b): fraction of axis b's force axis a reads; diag 0
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();    // rad/s, IMU axes: subtracted from every gyro reading
  double time_offset = 0.0;  // s: the accelerometer's sample at t saw the motion the gyro saw at t - time_offset
  // A constant wind in the world's horizontal plane, (north, east), m/s: drag acts on the air velocity, the ground
  // velocity minus the wind. The world's north is the identification's: the estimator starts its heading at
  // wind_heading, the yaw (rad) the identified flight had at its first sample, and integrates the gyro from there.
  Eigen::Vector2d wind = Eigen::Vector2d::Zero();
  double wind_heading = 0.0;

  friend bool operator==(const FullModelParams&, const FullModelParams&) = default;
};

// Why `p` is unusable (a non-finite value, a negative drag coefficient), or nullopt.
std::optional<std::string> validate(const FullModelParams& p);

// S = I + diag(accel_scale) + accel_cross: the accelerometer reads m = S f + accel_bias.
inline Eigen::Matrix3d sensor_matrix(const FullModelParams& p) {
  return Eigen::Matrix3d::Identity() + Eigen::Matrix3d(p.accel_scale.asDiagonal()) + p.accel_cross;
}

// The per-sample signals of the model; none depends on the parameters.
struct FullModelInput {
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();       // w_imu, rad/s, IMU axes
  Eigen::Vector3d gyro_rate = Eigen::Vector3d::Zero();  // w_dot_imu, rad/s^2, IMU axes
  Eigen::Vector2d velocity = Eigen::Vector2d::Zero();   // (v_x, v_y): body-axis horizontal air velocity, m/s
  double thrust = 0.0;                                  // T, m/s^2 (g under the paper's assumption)
};

// The specific force at the IMU in body axes, from the body rates: the mass centre's (drag, -T along z) plus the lever
// arm's w_dot x r + w x (w x r).
template <typename T>
Eigen::Matrix<T, 3, 1> body_specific_force(const T* lever_arm, const T* drag_linear, const T* drag_quadratic,
                                           const Eigen::Matrix<T, 3, 1>& w, const Eigen::Matrix<T, 3, 1>& w_dot,
                                           const FullModelInput& in) {
  using Vec3 = Eigen::Matrix<T, 3, 1>;
  const Eigen::Map<const Vec3> r(lever_arm);
  const Vec3 f_cm(drag_specific_force(drag_linear[0], drag_quadratic[0], in.velocity.x()),
                  drag_specific_force(drag_linear[1], drag_quadratic[1], in.velocity.y()), T(-in.thrust));
  return f_cm + w_dot.cross(r) + w.cross(w.cross(r));
}

// The predicted IMU specific force. The parameters come as separate raw blocks (3, 3, 2, 2, 3 values), the layout of
// Ceres parameter blocks, so an identification can hold any group constant. T is double or a ceres::Jet.
template <typename T>
Eigen::Matrix<T, 3, 1> predict_specific_force(const T* lever_arm, const T* mounting, const T* drag_linear,
                                              const T* drag_quadratic, const T* accel_bias, const FullModelInput& in) {
  using Vec3 = Eigen::Matrix<T, 3, 1>;
  const Vec3 w_imu = in.gyro.cast<T>();
  const Vec3 w_dot_imu = in.gyro_rate.cast<T>();
  Vec3 w;
  Vec3 w_dot;
  ceres::AngleAxisRotatePoint(mounting, w_imu.data(), w.data());
  ceres::AngleAxisRotatePoint(mounting, w_dot_imu.data(), w_dot.data());
  const Vec3 f_body = body_specific_force(lever_arm, drag_linear, drag_quadratic, w, w_dot, in);
  const T body_to_imu[3] = {-mounting[0], -mounting[1], -mounting[2]};
  Vec3 f_imu;
  ceres::AngleAxisRotatePoint(body_to_imu, f_body.data(), f_imu.data());
  return f_imu + Eigen::Map<const Vec3>(accel_bias);
}

inline Eigen::Vector3d predict_specific_force(const FullModelParams& p, const FullModelInput& in) {
  return predict_specific_force(p.lever_arm.data(), p.mounting.data(), p.drag_linear.data(), p.drag_quadratic.data(),
                                p.accel_bias.data(), in);
}

// The same for many samples of one model: `imu_to_body` is R_bs = Exp(p.mounting), computed once by the caller
// instead of three rotations by angle-axis per sample.
inline Eigen::Vector3d predict_specific_force(const FullModelParams& p, const Eigen::Matrix3d& imu_to_body,
                                              const FullModelInput& in) {
  const Eigen::Vector3d w = imu_to_body * in.gyro, w_dot = imu_to_body * in.gyro_rate;
  return imu_to_body.transpose() *
             body_specific_force(p.lever_arm.data(), p.drag_linear.data(), p.drag_quadratic.data(), w, w_dot, in) +
         p.accel_bias;
}

}  // namespace imubridge::estimator
