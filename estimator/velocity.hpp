#pragma once
// Velocity for the drag term. Without a reference: the paper's eq. (11)-(12) for pitch and its 3-D generalisation
// (gyro-integrated attitude, thrust along -z_b, no drag). With a reference: its world velocity in body axes.
// Both integrators use the trapezoidal rule: second-order accurate, exact for piecewise-linear rates, and free of
// the half-sample lag a rectangle rule would add. The paper does not say which rule it used.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <span>
#include <vector>

namespace imubridge::estimator {

// Eq. (11) theta = integral of omega_y + theta0, eq. (12) v_X = g * integral of sin(theta) + v_X0. v is the paper's
// v_X, the negative of the NED velocity V_X (docs/model.md).
struct PitchIntegration {
  std::vector<double> theta;  // rad
  std::vector<double> v;      // m/s, paper sign
};
PitchIntegration integrate_pitch(std::span<const double> t, std::span<const double> omega_y, double theta0 = 0.0,
                                 double v0 = 0.0);

// Strapdown without drag: q_k = q_{k-1} * Exp(dt * (w_{k-1} + w_k) / 2), v_k = v_{k-1} + dt * (a_{k-1} + a_k) / 2,
// a = q * (0, 0, -T) + (0, 0, g). gyro_body is in body axes (apply the mounting rotation first); thrust is T per
// sample (g for the paper's assumption). Drifts without bound: it is the paper's velocity, not an estimator.
struct DeadReckoning {
  std::vector<Eigen::Quaterniond> attitude;  // body -> NED
  std::vector<Eigen::Vector3d> velocity_ned;
};
DeadReckoning dead_reckon(std::span<const double> t, std::span<const Eigen::Vector3d> gyro_body,
                          std::span<const double> thrust, const Eigen::Quaterniond& q0 = Eigen::Quaterniond::Identity(),
                          const Eigen::Vector3d& v0 = Eigen::Vector3d::Zero());

// q^-1 * v_ned per sample: a reference's (or the dead reckoning's) velocity in body axes.
std::vector<Eigen::Vector3d> body_velocity(std::span<const Eigen::Quaterniond> attitude,
                                           std::span<const Eigen::Vector3d> velocity_ned);

}  // namespace imubridge::estimator
