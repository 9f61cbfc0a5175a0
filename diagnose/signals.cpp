#include "diagnose/signals.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

#include "diagnose/residual_analysis.hpp"
#include "estimator/velocity.hpp"
#include "identification/identify.hpp"

namespace imubridge::diagnose {
namespace {

using Eigen::Vector3d;

// The smallest rotation taking `direction` to -z: a levelled body frame whatever way up the sensor is mounted.
Vector3d levelling_rotation(const Vector3d& direction) {
  const Eigen::Quaterniond q = Eigen::Quaterniond::FromTwoVectors(direction, -Vector3d::UnitZ());
  const Eigen::AngleAxisd aa(q);
  return aa.angle() * aa.axis();
}

}  // namespace

Eigen::Matrix3d rotation_matrix(const Vector3d& rotation_vector) {
  const double angle = rotation_vector.norm();
  if (angle == 0.0) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(angle, rotation_vector / angle).toRotationMatrix();
}

Signals prepare_signals(const estimator::ImuSeries& series, double derivative_half_window) {
  estimator::require_valid(series);
  if (series.size() < 2) throw std::invalid_argument("diagnose: needs at least 2 samples");
  Signals s;
  s.t = series.t;
  s.rate_hz = sample_rate_hz(s.t);
  s.gyro = series.gyro;
  s.accel = series.accel;
  s.gyro_rate = estimator::smoothed_derivative(s.t, s.gyro, derivative_half_window);
  if (series.reference) {
    s.reference.emplace();
    s.reference->attitude = series.reference->attitude;
    s.reference->velocity_body = estimator::body_velocity(series.reference->attitude, series.reference->velocity_ned);
  }

  Vector3d mean_force = Vector3d::Zero();
  for (const Vector3d& f : s.accel) mean_force += f;
  if (mean_force.norm() == 0.0) throw std::invalid_argument("diagnose: the mean specific force is zero (no gravity?)");
  s.level_mounting = levelling_rotation(mean_force.normalized());
  const Eigen::Matrix3d imu_to_body = level_rotation(s);
  // Each levelled body axis's closest sensor axis: the largest entry of its row of R_bs.
  for (int axis = 0; axis < 2; ++axis) imu_to_body.row(axis).cwiseAbs().maxCoeff(&s.horizontal_sensor_axes[axis]);

  const std::size_t n = s.size();
  s.thrust.resize(n);
  s.tilt.resize(n);
  std::vector<double> roll_rate(n), pitch_rate(n);
  for (std::size_t k = 0; k < n; ++k) {
    const Vector3d body_rate = imu_to_body * s.gyro[k];
    roll_rate[k] = body_rate.x();
    pitch_rate[k] = body_rate.y();
    s.thrust[k] = -(imu_to_body * s.accel[k]).z();
  }
  const estimator::PitchIntegration roll = estimator::integrate_pitch(s.t, roll_rate);
  const estimator::PitchIntegration pitch = estimator::integrate_pitch(s.t, pitch_rate);
  for (std::size_t k = 0; k < n; ++k) s.tilt[k] = {roll.theta[k], pitch.theta[k]};
  return s;
}

std::size_t identification_block(double rate_hz) {
  const double block = std::round(rate_hz / kIdentificationRateHz);
  return block >= 1.0 ? static_cast<std::size_t>(block) : 1;
}

std::vector<estimator::ImuSample> block_means(std::span<const double> t, std::span<const Vector3d> gyro,
                                              std::span<const Vector3d> accel, std::size_t block, std::size_t blocks) {
  if (block == 0 || blocks * block > std::min({t.size(), gyro.size(), accel.size()}))
    throw std::invalid_argument("block_means: blocks beyond the signals");
  std::vector<estimator::ImuSample> out(blocks);
  const double scale = 1.0 / static_cast<double>(block);
  for (std::size_t j = 0; j < blocks; ++j) {
    estimator::ImuSample& m = out[j];
    m.t = 0.0, m.gyro.setZero(), m.accel.setZero();
    for (std::size_t k = j * block; k < (j + 1) * block; ++k) m.t += t[k], m.gyro += gyro[k], m.accel += accel[k];
    m.t *= scale, m.gyro *= scale, m.accel *= scale;
  }
  return out;
}

std::vector<NamedSignal> candidate_signals(const Signals& s, const std::vector<Vector3d>& velocity_body,
                                           std::size_t first, std::size_t count) {
  if (first + count > s.size() || velocity_body.size() != s.size())
    throw std::invalid_argument("candidate_signals: range or velocity length does not match the signals");
  static constexpr const char* kAxis[3] = {"x", "y", "z"};
  std::vector<NamedSignal> out;
  const auto add = [&](std::string name, auto value_of) {
    NamedSignal signal{std::move(name), std::vector<double>(count)};
    for (std::size_t k = 0; k < count; ++k) signal.values[k] = value_of(first + k);
    out.push_back(std::move(signal));
  };
  for (int a = 0; a < 3; ++a) add(std::string("gyro.") + kAxis[a], [&](std::size_t k) { return s.gyro[k][a]; });
  for (int a = 0; a < 3; ++a)
    add(std::string("gyro_rate.") + kAxis[a], [&](std::size_t k) { return s.gyro_rate[k][a]; });
  for (int a = 0; a < 3; ++a)
    add(std::string("gyro.") + kAxis[a] + "^2", [&](std::size_t k) { return s.gyro[k][a] * s.gyro[k][a]; });
  for (int a = 0; a < 3; ++a) add(std::string("accel.") + kAxis[a], [&](std::size_t k) { return s.accel[k][a]; });
  for (int a = 0; a < 2; ++a)
    add(std::string("velocity.") + kAxis[a], [&](std::size_t k) { return velocity_body[k][a]; });
  for (int a = 0; a < 2; ++a) add(std::string("tilt.") + kAxis[a], [&](std::size_t k) { return s.tilt[k][a]; });
  add("thrust", [&](std::size_t k) { return s.thrust[k]; });
  return out;
}

}  // namespace imubridge::diagnose
