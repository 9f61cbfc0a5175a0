#include "estimator/drag_velocity.hpp"

#include <limits>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "estimator/constants.hpp"
#include "estimator/drag_law.hpp"

namespace imubridge::estimator {
namespace {

// Keeps gamma_z = sqrt(1 - gamma_x^2 - gamma_y^2) away from zero, where the Jacobian divides by it. A quadrotor
// tilted beyond ~84 degrees is not flying the regime this filter models anyway.
constexpr double kMinGammaZ = 0.1;

const FullModelParams& checked(const FullModelParams& p) {
  if (auto error = validate(p)) throw std::invalid_argument("DragVelocityEstimator: " + *error);
  return p;
}

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

void check(const DragVelocityConfig& c) {
  const bool positive = c.max_gap > 0.0 && c.accel_noise > 0.0 && c.accel_process_noise > 0.0 && c.gyro_noise > 0.0 &&
                        c.gyro_bias_walk > 0.0 && c.initial_velocity_std > 0.0 && c.initial_tilt_std > 0.0 &&
                        c.initial_gyro_bias_std > 0.0 && c.max_specific_force > 0.0 && c.max_rate > 0.0;
  if (!positive) throw std::invalid_argument("DragVelocityEstimator: config times, noises and limits must be positive");
}

bool finite(const ImuSample& s) { return std::isfinite(s.t) && s.gyro.allFinite() && s.accel.allFinite(); }

}  // namespace

DragVelocityConfig config_for(const ModelParams& params, DragVelocityConfig base) {
  const auto& rmse = params.identification.rmse;
  // The channels an identification writes: the 3-D model's, else the paper's two axes (from which `full` derives).
  for (const char* model : {"full", "paper"}) {
    for (const char* set : {"validation", "fit"}) {
      const auto x = rmse.find(std::string(model) + ".x." + set);
      const auto y = rmse.find(std::string(model) + ".y." + set);
      if (x == rmse.end() || y == rmse.end()) continue;
      const double rms = std::sqrt(0.5 * (x->second * x->second + y->second * y->second));
      if (std::isfinite(rms)) base.accel_noise = std::max(base.accel_noise, rms);
      return base;
    }
  }
  return base;
}

DragVelocityEstimator::DragVelocityEstimator(const FullModelParams& params, const DragVelocityConfig& config)
    : params_(checked(params)), config_(config), compensator_(params), differentiator_(config.differentiator_window) {
  check(config);
  const auto square = [](double s) { return s * s; };
  process_density_ << square(config.accel_process_noise), square(config.accel_process_noise), square(config.gyro_noise),
      square(config.gyro_noise), square(config.gyro_bias_walk), square(config.gyro_bias_walk);
  // x_ starts level, at rest and unbiased, as a quadrotor on the ground is; the covariance says how sure that is.
  Vector6d initial_std;
  initial_std << config.initial_velocity_std, config.initial_velocity_std, config.initial_tilt_std,
      config.initial_tilt_std, config.initial_gyro_bias_std, config.initial_gyro_bias_std;
  p_ = initial_std.array().square().matrix().asDiagonal();
}

std::optional<DragVelocityEstimate> DragVelocityEstimator::update(const ImuSample& sample) {
  ++counters_.samples_in;
  if (!finite(sample)) {
    ++counters_.rejected_non_finite;
    return std::nullopt;
  }
  if (sample.accel.cwiseAbs().maxCoeff() > config_.max_specific_force ||
      sample.gyro.cwiseAbs().maxCoeff() > config_.max_rate) {
    ++counters_.rejected_out_of_range;
    return std::nullopt;
  }
  if (last_input_t_ && !(sample.t > *last_input_t_)) {
    ++counters_.rejected_time;
    return std::nullopt;
  }
  if (last_input_t_ && sample.t - *last_input_t_ > config_.max_gap) {
    ++counters_.gaps;
    differentiator_.reset();
    head_ = 0;
  }
  last_input_t_ = sample.t;

  const int window = differentiator_.window();
  history_[head_] = sample;
  head_ = (head_ + 1) % window;
  const std::optional<Eigen::Vector3d> gyro_rate = differentiator_.update(sample.t, sample.gyro);
  if (!gyro_rate) return std::nullopt;
  // The window is full: the oldest sample sits at head_, the centre delay_samples() after it.
  const ImuSample& centre = history_[(head_ + delay_samples()) % window];

  const Eigen::Vector3d f_cm = compensator_.compensate(centre.accel, centre.gyro, *gyro_rate);
  if (filter_t_) {
    const double dt = centre.t - *filter_t_;
    if (dt <= config_.max_gap) {
      predict(dt, compensator_.to_body(centre.gyro));
    } else {
      // No rates across the gap: keep the state and grow the uncertainty as the process noise would.
      p_.diagonal() += process_density_ * dt;
    }
  }
  filter_t_ = centre.t;

  DragVelocityEstimate out;
  out.t = centre.t;
  out.f = f_cm.head<2>();
  const double f_var = config_.accel_noise * config_.accel_noise;
  for (int axis = 0; axis < 2; ++axis) {
    out.f_var[axis] = f_var;
    if (!has_drag(axis)) {  // not identified yet: the force is still compensated, the velocity is unknown
      out.v_raw[axis] = out.v_raw_var[axis] = out.v[axis] = out.v_var[axis] = kNaN;
      continue;
    }
    const double k = params_.drag_linear[axis];
    const double mu = params_.drag_quadratic[axis];
    const double v_raw = invert_drag(k, mu, out.f[axis]);
    const double slope = drag_slope(k, mu, v_raw);
    out.v_raw[axis] = v_raw;
    out.v_raw_var[axis] = f_var / (slope * slope);
    fuse_velocity(axis, v_raw);
    out.v[axis] = x_[axis];
    out.v_var[axis] = p_(axis, axis);
  }
  out.gyro_bias = x_.tail<2>();
  ++counters_.estimates_out;
  return out;
}

void DragVelocityEstimator::predict(double dt, const Eigen::Vector3d& w_measured) {
  const double vx = x_[0], vy = x_[1], gx = x_[2], gy = x_[3];
  const double wx = w_measured.x() - x_[4];
  const double wy = w_measured.y() - x_[5];
  const double wz = w_measured.z();  // yaw-rate bias is not observable from horizontal drag; left in the noise
  const double gz = std::sqrt(std::max(1.0 - gx * gx - gy * gy, kMinGammaZ * kMinGammaZ));
  const double kx = params_.drag_linear.x(), ky = params_.drag_linear.y();
  const double mux = params_.drag_quadratic.x(), muy = params_.drag_quadratic.y();

  // Body-frame velocity: v_dot = drag(v) + g*gamma - w x v (horizontal rows; the w x v terms through the small
  // vertical body velocity are left to the process noise). Gravity direction in body axes: gamma_dot = -w x gamma.
  Vector6d x_dot;
  x_dot << drag_specific_force(kx, mux, vx) + kGravity * gx + wz * vy,
      drag_specific_force(ky, muy, vy) + kGravity * gy - wz * vx, wz * gy - wy * gz, wx * gz - wz * gx, 0.0, 0.0;

  Matrix6d a = Matrix6d::Zero();
  a.row(0) << -drag_slope(kx, mux, vx), wz, kGravity, 0.0, 0.0, 0.0;
  a.row(1) << -wz, -drag_slope(ky, muy, vy), 0.0, kGravity, 0.0, 0.0;
  a.row(2) << 0.0, 0.0, wy * gx / gz, wz + wy * gy / gz, 0.0, gz;
  a.row(3) << 0.0, 0.0, -wz - wx * gx / gz, -wx * gy / gz, -gz, 0.0;

  x_ += x_dot * dt;
  const Matrix6d f = Matrix6d::Identity() + a * dt;
  p_ = f * p_ * f.transpose();
  p_.diagonal() += process_density_ * dt;
}

void DragVelocityEstimator::fuse_velocity(int axis, double v_measured) {
  // The inversion's noise is the accelerometer's divided by the law's slope, taken at the prediction rather than at
  // the noisy measurement. A zero slope (pure quadratic drag at rest) carries no information: skip.
  const double slope = drag_slope(params_.drag_linear[axis], params_.drag_quadratic[axis], x_[axis]);
  if (!(slope > 0.0)) return;
  const double r = config_.accel_noise * config_.accel_noise / (slope * slope);
  const Vector6d gain = p_.col(axis) / (p_(axis, axis) + r);
  x_ += gain * (v_measured - x_[axis]);
  p_ -= gain * p_.row(axis);
  p_ = (0.5 * (p_ + p_.transpose())).eval();
}

}  // namespace imubridge::estimator
