#include "sim/controller.hpp"

#include <algorithm>
#include <cmath>

namespace imubridge::sim {

using Eigen::Vector2d;
using Eigen::Vector3d;
using Eigen::Vector4d;

Vector3d euler_zyx(const Eigen::Quaterniond& attitude) {
  const Eigen::Matrix3d c = attitude.toRotationMatrix();  // C_b^e, eq. (5)
  return {std::atan2(c(2, 1), c(2, 2)), std::asin(std::clamp(-c(2, 0), -1.0, 1.0)), std::atan2(c(1, 0), c(0, 0))};
}

Vector4d Controller::rotor_command(const RigidState& s, const FlightReference& ref) const {
  const QuadrotorParams& p = vehicle_.params();
  const ControllerGains& g = gains_;
  const Vector3d euler = euler_zyx(s.attitude);

  // Position hold: the horizontal acceleration wanted, in the heading frame, turned into tilt by eq. (1) at small
  // angles (nose down accelerates forward, right side down accelerates right).
  const Vector2d accel_ned = -g.position_kp * (s.position - hold_).head<2>() - g.position_kd * s.velocity.head<2>();
  const Vector2d accel_heading = Eigen::Rotation2Dd(-euler.z()) * accel_ned;
  const double pitch_hold = std::clamp(-accel_heading.x() / kGravity, -g.max_hold_tilt_rad, g.max_hold_tilt_rad);
  const double roll_hold = std::clamp(accel_heading.y() / kGravity, -g.max_hold_tilt_rad, g.max_hold_tilt_rad);

  const Vector3d angular_accel{ref.roll.acceleration + g.attitude_kp * (ref.roll.value + roll_hold - euler.x()) +
                                   g.attitude_kd * (ref.roll.rate - s.omega.x()),
                               ref.pitch.acceleration + g.attitude_kp * (ref.pitch.value + pitch_hold - euler.y()) +
                                   g.attitude_kd * (ref.pitch.rate - s.omega.y()),
                               g.yaw_rate_kp * (ref.yaw_rate - s.omega.z())};
  // Inverse of Euler's equation: also cancel the rigid-body and gyroscopic torques.
  const Vector3d& inertia = p.inertia_kgm2;
  const Vector3d rotors = vehicle_.rotor_momentum(s.rotor_speed) * Vector3d::UnitZ();
  const Vector3d torque =
      inertia.cwiseProduct(angular_accel) + s.omega.cross(inertia.cwiseProduct(s.omega)) + s.omega.cross(rotors);

  // Altitude hold at the reference height (up, so down is its negative); eq. (1)'s z row,
  // Zdd = g - cos(phi) cos(theta) U1, solved for the thrust.
  const double accel_down = -ref.height.acceleration +
                            g.altitude_kp * (hold_.z() - ref.height.value - s.position.z()) -
                            g.altitude_kd * (s.velocity.z() + ref.height.rate);
  const double cos_tilt = std::max(0.5, std::cos(euler.x()) * std::cos(euler.y()));
  const double thrust = p.mass_kg * (kGravity - accel_down) / cos_tilt;

  // Eq. (2) inverted for the rotor thrusts b * Omega_i^2.
  const double pitch_share = torque.y() / (2 * p.arm_m);
  const double roll_share = torque.x() / (2 * p.arm_m);
  const double yaw_share = torque.z() * p.thrust_factor / (4 * p.drag_factor);
  const Vector4d rotor_thrust{thrust / 4 + pitch_share + yaw_share, thrust / 4 - roll_share - yaw_share,
                              thrust / 4 - pitch_share + yaw_share, thrust / 4 + roll_share - yaw_share};
  return (rotor_thrust.cwiseMax(0.0) / p.thrust_factor).cwiseSqrt();
}

}  // namespace imubridge::sim
