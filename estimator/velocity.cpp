#include "estimator/velocity.hpp"

#include <cmath>
#include <stdexcept>

#include "estimator/constants.hpp"

namespace imubridge::estimator {
namespace {

void require_same_length(std::size_t a, std::size_t b, const char* what) {
  if (a != b) throw std::invalid_argument(std::string(what) + ": input lengths differ");
}

}  // namespace

PitchIntegration integrate_pitch(std::span<const double> t, std::span<const double> omega_y, double theta0, double v0) {
  require_same_length(t.size(), omega_y.size(), "integrate_pitch");
  PitchIntegration out{std::vector<double>(t.size()), std::vector<double>(t.size())};
  if (t.empty()) return out;
  out.theta[0] = theta0;
  out.v[0] = v0;
  for (std::size_t k = 1; k < t.size(); ++k) {
    const double dt = t[k] - t[k - 1];
    out.theta[k] = out.theta[k - 1] + 0.5 * dt * (omega_y[k - 1] + omega_y[k]);
    out.v[k] = out.v[k - 1] + 0.5 * dt * kGravity * (std::sin(out.theta[k - 1]) + std::sin(out.theta[k]));
  }
  return out;
}

DeadReckoning dead_reckon(std::span<const double> t, std::span<const Eigen::Vector3d> gyro_body,
                          std::span<const double> thrust, const Eigen::Quaterniond& q0, const Eigen::Vector3d& v0) {
  require_same_length(t.size(), gyro_body.size(), "dead_reckon");
  require_same_length(t.size(), thrust.size(), "dead_reckon");
  const auto acceleration = [&](const Eigen::Quaterniond& q, double T) {
    return Eigen::Vector3d(q * Eigen::Vector3d(0.0, 0.0, -T) + Eigen::Vector3d(0.0, 0.0, kGravity));
  };
  DeadReckoning out;
  out.attitude.reserve(t.size());
  out.velocity_ned.reserve(t.size());
  if (t.empty()) return out;
  out.attitude.push_back(q0.normalized());
  out.velocity_ned.push_back(v0);
  for (std::size_t k = 1; k < t.size(); ++k) {
    const double dt = t[k] - t[k - 1];
    const Eigen::Vector3d rotation = 0.5 * dt * (gyro_body[k - 1] + gyro_body[k]);
    const double angle = rotation.norm();
    Eigen::Quaterniond q = out.attitude[k - 1];
    if (angle > 0.0) q = (q * Eigen::Quaterniond(Eigen::AngleAxisd(angle, rotation / angle))).normalized();
    const Eigen::Vector3d a0 = acceleration(out.attitude[k - 1], thrust[k - 1]);
    out.velocity_ned.push_back(out.velocity_ned[k - 1] + 0.5 * dt * (a0 + acceleration(q, thrust[k])));
    out.attitude.push_back(q);
  }
  return out;
}

std::vector<Eigen::Vector3d> body_velocity(std::span<const Eigen::Quaterniond> attitude,
                                           std::span<const Eigen::Vector3d> velocity_ned) {
  require_same_length(attitude.size(), velocity_ned.size(), "body_velocity");
  std::vector<Eigen::Vector3d> out(attitude.size());
  for (std::size_t k = 0; k < attitude.size(); ++k) out[k] = attitude[k].conjugate() * velocity_ned[k];
  return out;
}

}  // namespace imubridge::estimator
