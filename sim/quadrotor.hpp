#pragma once
// The vehicle: a rigid body with four rotors in "+" layout (the paper's eq. 1-3), integrated with fixed-step RK4.
// Frames as in docs/model.md: NED world, FRD body, thrust along -z_b.
#include <Eigen/Geometry>

namespace imubridge::sim {

inline constexpr double kGravity = 9.80665;  // m/s^2, +z in NED

// Defaults: rough values for a 320 g frame like the paper's (hover at ~720 rad/s, thrust/weight ~4).
struct QuadrotorParams {
  double mass_kg = 0.32;
  Eigen::Vector3d inertia_kgm2{3.5e-3, 3.5e-3, 6.5e-3};  // principal moments along x_b, y_b, z_b
  double arm_m = 0.2;                                    // l: mass centre to each rotor axis
  double thrust_factor = 1.5e-6;                         // b: one rotor's thrust b*Omega^2, N s^2
  double drag_factor = 2.4e-8;                           // d: one rotor's reaction torque d*Omega^2, N m s^2
  double rotor_inertia_kgm2 = 1.5e-5;                    // J_TP of eq. (1)
  double motor_time_constant_s = 0.015;                  // rotor speed follows its command with this lag
  double max_rotor_speed = 1500.0;                       // rad/s

  double hover_rotor_speed() const;
};

// Air acting on the body. Drag uses the air velocity (ground velocity - wind) in body axes, horizontal components
// only, applied per axis as in docs/model.md: f_i = -k*v_i - mu*|v_i|*v_i, i in {x_b, y_b}.
struct Aerodynamics {
  double quadratic_drag_per_m = 0.0;  // mu, the paper's eq. (13)
  double linear_drag_per_s = 0.0;     // k, rotor (momentum) drag
  Eigen::Vector3d wind_ned = Eigen::Vector3d::Zero();
};

struct RigidState {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();            // mass centre, NED, m
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();            // NED, m/s
  Eigen::Quaterniond attitude = Eigen::Quaterniond::Identity();  // body -> NED
  Eigen::Vector3d omega = Eigen::Vector3d::Zero();               // body rates, rad/s
  Eigen::Vector4d rotor_speed = Eigen::Vector4d::Zero();         // Omega_1..4: front, right, rear, left, rad/s
};

class Quadrotor {
 public:
  Quadrotor(const QuadrotorParams& params, const Aerodynamics& air) : params_(params), air_(air) {}

  // At rest at `position`, level, rotors at hover speed.
  RigidState hover_at(const Eigen::Vector3d& position) const;

  Eigen::Vector3d air_velocity_body(const RigidState& s) const;
  // Thrust plus drag per unit mass, body axes: what an accelerometer at the mass centre reads.
  Eigen::Vector3d specific_force(const RigidState& s) const;
  Eigen::Vector3d angular_acceleration(const RigidState& s) const;
  // Rotor angular momentum along z_b, J_TP * (-Omega_1 + Omega_2 - Omega_3 + Omega_4) (eq. 3).
  double rotor_momentum(const Eigen::Vector4d& rotor_speed) const;

  // One RK4 step of length dt with the rotor commands held constant (rad/s, clamped to [0, max]).
  RigidState step(const RigidState& s, const Eigen::Vector4d& rotor_command, double dt) const;

  const QuadrotorParams& params() const { return params_; }

 private:
  struct Rate;
  Rate rate(const RigidState& s, const Eigen::Vector4d& rotor_command) const;

  QuadrotorParams params_;
  Aerodynamics air_;
};

}  // namespace imubridge::sim
