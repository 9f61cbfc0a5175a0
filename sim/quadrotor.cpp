#include "sim/quadrotor.hpp"

#include <cmath>

namespace imubridge::sim {

using Eigen::Vector3d;
using Eigen::Vector4d;

struct Quadrotor::Rate {
  Vector3d velocity, acceleration;
  Vector4d attitude;  // quaternion coefficient rates, Eigen's (x, y, z, w) order
  Vector3d omega_dot;
  Vector4d rotor_accel;
};

namespace {

// s + h * r, renormalising the attitude so every RK4 stage sees a proper rotation.
RigidState advanced(const RigidState& s, const auto& r, double h) {
  RigidState out;
  out.position = s.position + h * r.velocity;
  out.velocity = s.velocity + h * r.acceleration;
  out.attitude.coeffs() = s.attitude.coeffs() + h * r.attitude;
  out.attitude.normalize();
  out.omega = s.omega + h * r.omega_dot;
  out.rotor_speed = s.rotor_speed + h * r.rotor_accel;
  return out;
}

}  // namespace

double QuadrotorParams::hover_rotor_speed() const { return std::sqrt(mass_kg * kGravity / (4.0 * thrust_factor)); }

RigidState Quadrotor::hover_at(const Vector3d& position) const {
  RigidState s;
  s.position = position;
  s.rotor_speed.setConstant(params_.hover_rotor_speed());
  return s;
}

Vector3d Quadrotor::air_velocity_body(const RigidState& s) const {
  return s.attitude.conjugate() * (s.velocity - air_.wind_ned);
}

Vector3d Quadrotor::specific_force(const RigidState& s) const {
  const Vector3d v = air_velocity_body(s);
  const auto drag = [&](double vi) {
    return -air_.linear_drag_per_s * vi - air_.quadratic_drag_per_m * std::abs(vi) * vi;
  };
  const double thrust = params_.thrust_factor * s.rotor_speed.squaredNorm() / params_.mass_kg;
  return {drag(v.x()), drag(v.y()), -thrust};
}

double Quadrotor::rotor_momentum(const Vector4d& w) const {
  return params_.rotor_inertia_kgm2 * (-w[0] + w[1] - w[2] + w[3]);
}

Vector3d Quadrotor::angular_acceleration(const RigidState& s) const {
  const Vector4d w2 = s.rotor_speed.cwiseAbs2();
  const double lb = params_.arm_m * params_.thrust_factor;
  // Eq. (2): left rotor rolls right-wing-down, front rotor pitches nose-up, rotors 1 and 3 yaw nose-right.
  const Vector3d torque{lb * (w2[3] - w2[1]), lb * (w2[0] - w2[2]),
                        params_.drag_factor * (w2[0] - w2[1] + w2[2] - w2[3])};
  const Vector3d& I = params_.inertia_kgm2;
  const Vector3d& w = s.omega;
  const Vector3d rotors = rotor_momentum(s.rotor_speed) * Vector3d::UnitZ();
  // Euler's equation; -w x (I w) and -w x rotors are eq. (1)'s I_X*q*r and gyroscopic J_TP terms.
  return (torque - w.cross(I.cwiseProduct(w)) - w.cross(rotors)).cwiseQuotient(I);
}

Quadrotor::Rate Quadrotor::rate(const RigidState& s, const Vector4d& rotor_command) const {
  Rate r;
  r.velocity = s.velocity;
  r.acceleration = s.attitude * specific_force(s) + kGravity * Vector3d::UnitZ();
  const Eigen::Quaterniond omega_quat(0.0, s.omega.x(), s.omega.y(), s.omega.z());
  r.attitude = 0.5 * (s.attitude * omega_quat).coeffs();
  r.omega_dot = angular_acceleration(s);
  const Vector4d command = rotor_command.cwiseMax(0.0).cwiseMin(params_.max_rotor_speed);
  r.rotor_accel = (command - s.rotor_speed) / params_.motor_time_constant_s;
  return r;
}

RigidState Quadrotor::step(const RigidState& s, const Vector4d& u, double dt) const {
  const Rate k1 = rate(s, u);
  const Rate k2 = rate(advanced(s, k1, dt / 2), u);
  const Rate k3 = rate(advanced(s, k2, dt / 2), u);
  const Rate k4 = rate(advanced(s, k3, dt), u);
  Rate sum;
  sum.velocity = k1.velocity + 2 * k2.velocity + 2 * k3.velocity + k4.velocity;
  sum.acceleration = k1.acceleration + 2 * k2.acceleration + 2 * k3.acceleration + k4.acceleration;
  sum.attitude = k1.attitude + 2 * k2.attitude + 2 * k3.attitude + k4.attitude;
  sum.omega_dot = k1.omega_dot + 2 * k2.omega_dot + 2 * k3.omega_dot + k4.omega_dot;
  sum.rotor_accel = k1.rotor_accel + 2 * k2.rotor_accel + 2 * k3.rotor_accel + k4.rotor_accel;
  return advanced(s, sum, dt / 6);
}

}  // namespace imubridge::sim
