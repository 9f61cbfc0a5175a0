#pragma once
// Flight controller: roll/pitch angle PD with the reference's rate and acceleration fed forward, yaw-rate P,
// altitude PD around the reference height (its rate and acceleration fed forward) and a weak horizontal position
// hold. Stateless, so the flight is a pure function of the state.
#include <Eigen/Core>

#include "sim/quadrotor.hpp"
#include "sim/trajectory.hpp"

namespace imubridge::sim {

struct ControllerGains {
  double attitude_kp = 225.0, attitude_kd = 24.0;  // 1/s^2, 1/s: ~15 rad/s, well damped despite the motor lag
  double yaw_rate_kp = 10.0;                       // 1/s
  double altitude_kp = 4.0, altitude_kd = 4.0;     // 1/s^2, 1/s
  double position_kp = 0.25, position_kd = 0.7;    // weak: manoeuvres move the vehicle, the hold brings it back
  double max_hold_tilt_rad = 0.2;
};

// The "Euler angles" of eq. (5): ZYX roll phi, pitch theta, yaw psi of a body -> NED rotation.
Eigen::Vector3d euler_zyx(const Eigen::Quaterniond& attitude);

class Controller {
 public:
  // Holds the horizontal position of `hold_position`, and its altitude plus the reference's height.
  Controller(const Quadrotor& vehicle, const ControllerGains& gains, const Eigen::Vector3d& hold_position)
      : vehicle_(vehicle), gains_(gains), hold_(hold_position) {}

  // Rotor speed commands (rad/s, front, right, rear, left).
  Eigen::Vector4d rotor_command(const RigidState& s, const FlightReference& ref) const;

 private:
  Quadrotor vehicle_;  // the controller knows the vehicle exactly: it inverts eq. (1)-(2)
  ControllerGains gains_;
  Eigen::Vector3d hold_;
};

}  // namespace imubridge::sim
