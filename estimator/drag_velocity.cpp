#include "estimator/drag_velocity.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "estimator/constants.hpp"
#include "estimator/drag_law.hpp"

namespace imubridge::estimator {
namespace {

// The velocity error an unknown accelerometer offset of std `offset_std` gives at the estimate v: what a force that
// far either side reads as through the drag law's inverse (RMS of the two). For a linear law that is offset_std / k,
// computed so. For a quadratic one the tangent at v claims far less near rest, where the inverse is steep: a
// one-sigma offset read at rest makes v = sqrt(offset / mu), and offset / slope(v) is half of that.
double offset_velocity(double k, double mu, double v, double offset_std) {
  if (mu == 0.0 || offset_std == 0.0) return offset_std / std::max(drag_slope(k, mu, v), 1e-9);
  const double f = drag_specific_force(k, mu, v);
  const double up = invert_drag(k, mu, f - offset_std) - v;  // the law opposes motion: less force, more speed
  const double down = v - invert_drag(k, mu, f + offset_std);
  return std::sqrt(0.5 * (up * up + down * down));
}

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
                        c.initial_gyro_bias_std > 0.0 && c.max_specific_force > 0.0 && c.max_rate > 0.0 &&
                        c.accel_offset_std >= 0.0 && c.wind_std >= 0.0 && c.rest_speed_std > 0.0 &&
                        c.landed_speed_std > 0.0;
  if (!positive) throw std::invalid_argument("DragVelocityEstimator: config times, noises and limits must be positive");
}

bool finite(const ImuSample& s) { return std::isfinite(s.t) && s.gyro.allFinite() && s.accel.allFinite(); }

}  // namespace

DragVelocityConfig config_for(const ModelParams& params, DragVelocityConfig base) {
  if (params.identification.process_noise > 0.0) base.accel_process_noise = params.identification.process_noise;
  if (params.transferred) {
    // Measured on the flights that validated the calibration when it was (params.hpp), else a MEMS datasheet's.
    base.accel_offset_std =
        std::max(base.accel_offset_std, params.identification.transfer_offset_std.value_or(kTransferredOffsetStd));
    // A measured offset std already counts the wind: it is what made the validating flights' NEES honest.
    if (!params.identification.transfer_offset_std) base.wind_std = std::max(base.wind_std, kTransferredWindStd);
  } else if (params.identification.process_noise > 0.0) {
    // Fitted from the IMU alone (the filter error method fits the process noise): on a steady heading nothing in the
    // IMU places the accelerometer's offset, so even on the flight it was fitted on the fit did not place it.
    base.accel_offset_std = std::max(base.accel_offset_std, kTransferredOffsetStd);
  }
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
  p_ = initial_covariance(config.initial_velocity_std);
  if (params_.time_offset != 0.0) ring_.resize(kAlignerCapacity);
  windy_ = params_.wind != Eigen::Vector2d::Zero();
  heading_cos_ = std::cos(params_.wind_heading);
  heading_sin_ = std::sin(params_.wind_heading);
}

bool DragVelocityEstimator::align(ImuSample& sample) {
  const bool gyro_late = params_.time_offset > 0.0;  // the gyro of t - time_offset is in the past: delay it
  const std::size_t capacity = ring_.size();
  ring_[ring_sequence_ % capacity] = {sample.t, gyro_late ? sample.gyro : sample.accel};
  ++ring_sequence_;
  ring_size_ = std::min(ring_size_ + 1, capacity);
  const std::uint64_t oldest = ring_sequence_ - ring_size_;
  const auto at = [&](std::uint64_t n) -> const Stamped& { return ring_[n % capacity]; };

  // Query times only increase, so the cursor only moves forward: amortised O(1).
  const double query = sample.t - std::abs(params_.time_offset);
  ring_cursor_ = std::max(ring_cursor_, oldest);
  if (at(ring_cursor_).t > query) return false;  // not |time_offset| of history yet
  while (ring_cursor_ + 1 < ring_sequence_ && at(ring_cursor_ + 1).t <= query) ++ring_cursor_;
  // The current sample is newer than the query, so the bracket's upper end exists.
  const Stamped& before = at(ring_cursor_);
  const Stamped& after = at(ring_cursor_ + 1);
  const Eigen::Vector3d value =
      before.value + (after.value - before.value) * ((query - before.t) / (after.t - before.t));
  (gyro_late ? sample.gyro : sample.accel) = value;
  return true;
}

std::optional<DragVelocityEstimate> DragVelocityEstimator::update(const ImuSample& sample) {
  ++counters_.samples_in;
  if (!accept(sample)) return std::nullopt;
  // The identified gyro bias goes first: everything downstream (alignment, differentiation, compensation,
  // propagation) wants the rate itself; the filter's bias states then track what is left.
  ImuSample input{sample.t, sample.gyro - params_.gyro_bias, sample.accel};
  if (!ring_.empty() && !align(input)) {
    ++counters_.aligning;
    return std::nullopt;
  }

  const int window = differentiator_.window();
  history_[head_] = input;
  head_ = (head_ + 1) % window;
  const std::optional<Eigen::Vector3d> gyro_rate = differentiator_.update(input.t, input.gyro);
  if (!gyro_rate) return std::nullopt;
  // The window is full: the oldest sample sits at head_, the centre delay_samples() after it.
  const ImuSample& centre = history_[(head_ + delay_samples()) % window];

  const Eigen::Vector3d f_cm = compensator_.compensate(centre.accel, centre.gyro, *gyro_rate);
  propagate_to(centre, f_cm.head<2>());

  DragVelocityEstimate out;
  out.t = centre.t;
  out.f = f_cm.head<2>();
  const WindLinearisation wind = linearise_wind();
  for (int axis = 0; axis < 2; ++axis) fuse_axis(axis, wind, out);
  if (diverged()) reset_after_divergence(out);
  out.gyro_bias = x_.tail<2>();
  ++counters_.estimates_out;
  if (landed_) ++counters_.landed;
  return out;
}

bool DragVelocityEstimator::accept(const ImuSample& sample) {
  if (!finite(sample)) {
    ++counters_.rejected_non_finite;
    return false;
  }
  if (sample.accel.cwiseAbs().maxCoeff() > config_.max_specific_force ||
      sample.gyro.cwiseAbs().maxCoeff() > config_.max_rate) {
    ++counters_.rejected_out_of_range;
    return false;
  }
  if (last_input_t_ && !(sample.t > *last_input_t_)) {
    ++counters_.rejected_time;
    return false;
  }
  if (last_input_t_ && sample.t - *last_input_t_ > config_.max_gap) {
    ++counters_.gaps;
    restart_window();
  }
  last_input_t_ = sample.t;
  return true;
}

void DragVelocityEstimator::propagate_to(const ImuSample& centre, const Eigen::Vector2d& force) {
  if (filter_t_) {
    const double dt = centre.t - *filter_t_;
    if (dt <= config_.max_gap) {
      predict(dt, compensator_.to_body(centre.gyro), landed_ ? &force : nullptr);
    } else {
      // No rates across the gap: keep the state and grow the uncertainty as the process noise would.
      p_.diagonal() += process_density_ * dt;
    }
  }
  filter_t_ = centre.t;
}

DragVelocityEstimator::WindLinearisation DragVelocityEstimator::linearise_wind() const {
  WindLinearisation w;
  if (windy_) {
    w.wind = wind_in_body(&w.jacobian);
    w.predicted_tilt = x_.segment<2>(2);
  }
  return w;
}

void DragVelocityEstimator::fuse_axis(int axis, const WindLinearisation& w, DragVelocityEstimate& out) {
  const double f_var = config_.accel_noise * config_.accel_noise;
  out.f_var[axis] = f_var;
  const double k = params_.drag_linear[axis];
  const double mu = params_.drag_quadratic[axis];
  // The first axis's update moved the tilt: carry the wind's projection along to first order.
  const double wind_now = windy_ ? w.wind[axis] + w.jacobian.row(axis).dot(x_.segment<2>(2) - w.predicted_tilt) : 0.0;
  out.prior_air_velocity[axis] = x_[axis] - wind_now;
  out.innovation[axis] = out.f[axis] - drag_specific_force(k, mu, out.prior_air_velocity[axis]);
  const double prior_slope = fusion_slope(axis, out.prior_air_velocity[axis]);
  out.innovation_var[axis] = prior_slope * prior_slope * p_(axis, axis) + f_var;
  if (landed_) return fuse_zero_velocity(axis, out);
  if (!has_drag(axis)) {
    // Nothing reads this axis's velocity. A model with drag on the other axis is a velocity estimator that knows
    // nothing here: rest, as sure as the prior (weigh_against_rest as k -> 0), never a speed nobody measured. With
    // drag on neither axis nothing is identified yet: unknown.
    const bool estimating = has_drag(1 - axis);
    const double rest = config_.rest_speed_std * config_.rest_speed_std;
    out.v_raw[axis] = out.v[axis] = estimating ? 0.0 : kNaN;
    out.v_raw_var[axis] = out.v_var[axis] = estimating ? rest : kNaN;
    return;
  }
  const double v_raw = invert_drag(k, mu, out.f[axis]);
  const double slope = drag_slope(k, mu, v_raw);
  out.v_raw[axis] = v_raw;
  out.v_raw_var[axis] = f_var / (slope * slope);
  if (windy_) {
    out.v_raw[axis] = v_raw + w.wind[axis];
    fuse_air_velocity(axis, v_raw, wind_now, w.jacobian.row(axis).transpose());
  } else {
    fuse_velocity(axis, v_raw);
  }
  weigh_against_rest(axis, out);
}

void DragVelocityEstimator::weigh_against_rest(int axis, DragVelocityEstimate& out) const {
  const double k = params_.drag_linear[axis];
  const double mu = params_.drag_quadratic[axis];
  // The filter's velocity carries, beside its own variance, the offset's (offset_velocity), constant through the
  // flight. Weighed against rest (a Gaussian prior of std rest_speed_std), the product of the two is the output.
  const double offset = offset_velocity(k, mu, x_[axis], config_.accel_offset_std);
  const double known = p_(axis, axis) + offset * offset + config_.wind_std * config_.wind_std;
  const double rest = config_.rest_speed_std * config_.rest_speed_std;
  out.v[axis] = x_[axis] * rest / (rest + known);
  out.v_var[axis] = known * rest / (rest + known);
}

DragVelocityEstimator::Matrix6d DragVelocityEstimator::initial_covariance(double velocity_std) const {
  Vector6d std;
  std << velocity_std, velocity_std, config_.initial_tilt_std, config_.initial_tilt_std, config_.initial_gyro_bias_std,
      config_.initial_gyro_bias_std;
  return std.array().square().matrix().asDiagonal();
}

bool DragVelocityEstimator::diverged() const {
  // No velocity is ever known to a tenth of a millimetre per second (the legs' own is 0.05 m/s): a variance below is
  // the covariance losing its positive definiteness, a step before it turns NaN and never recovers.
  constexpr double kMinVelocityVariance = 1e-8;  // (m/s)^2: 0.1 mm/s
  return !x_.allFinite() || !p_.allFinite() || !(p_(0, 0) > kMinVelocityVariance) ||
         !(p_(1, 1) > kMinVelocityVariance) || !(p_.diagonal().minCoeff() > 0.0);
}

void DragVelocityEstimator::reset_after_divergence(DragVelocityEstimate& out) {
  ++counters_.resets;
  // Level, at rest and unbiased, as at the start: whatever wrecked the covariance wrecked every state with it.
  x_.setZero();
  p_ = initial_covariance(config_.rest_speed_std);
  for (int axis = 0; axis < 2; ++axis) {
    if (landed_) {
      out.v[axis] = x_[axis];
      out.v_var[axis] = p_(axis, axis);
    } else if (has_drag(axis)) {
      weigh_against_rest(axis, out);
    }
  }
}

void DragVelocityEstimator::restart_window() {
  differentiator_.reset();
  head_ = 0;
  ring_sequence_ = ring_cursor_ = 0;  // no interpolation across the gap
  ring_size_ = 0;
}

void DragVelocityEstimator::restart_clock(double elapsed) {
  ++counters_.clock_restarts;
  restart_window();
  last_input_t_.reset();
  // The next estimate's time has no relation to filter_t_: it does not predict, and the time between is accounted
  // here, as a gap without rates would be.
  if (filter_t_) p_.diagonal() += process_density_ * std::max(elapsed, 0.0);
  filter_t_.reset();
}

void DragVelocityEstimator::predict(double dt, const Eigen::Vector3d& w_measured, const Eigen::Vector2d* held_force) {
  const double vx = x_[0], vy = x_[1], gx = x_[2], gy = x_[3];
  const double wx = w_measured.x() - x_[4];
  const double wy = w_measured.y() - x_[5];
  const double wz = w_measured.z();  // yaw-rate bias is not observable from horizontal drag; left in the noise
  const double gz = std::sqrt(std::max(1.0 - gx * gx - gy * gy, kMinGammaZ * kMinGammaZ));
  // In the air the horizontal force is the drag of the air velocity, v - R^T w (v itself without wind); on the ground
  // it is what the accelerometer measures, whatever holds the vehicle, and depends on no state.
  double force_x = 0.0, force_y = 0.0, slope_x = 0.0, slope_y = 0.0;
  Eigen::Matrix2d wind_jacobian = Eigen::Matrix2d::Zero();
  if (held_force) {
    force_x = held_force->x();
    force_y = held_force->y();
  } else {
    const double kx = params_.drag_linear.x(), ky = params_.drag_linear.y();
    const double mux = params_.drag_quadratic.x(), muy = params_.drag_quadratic.y();
    double ax = vx, ay = vy;
    if (windy_) {
      const Eigen::Vector2d wind = wind_in_body(&wind_jacobian);
      ax = vx - wind.x();
      ay = vy - wind.y();
    }
    force_x = drag_specific_force(kx, mux, ax);
    force_y = drag_specific_force(ky, muy, ay);
    slope_x = drag_slope(kx, mux, ax);
    slope_y = drag_slope(ky, muy, ay);
  }

  // Body-frame velocity: v_dot = force + g*gamma - w x v (horizontal rows; the w x v terms through the small
  // vertical body velocity are left to the process noise). Gravity direction in body axes: gamma_dot = -w x gamma.
  Vector6d x_dot;
  x_dot << force_x + kGravity * gx + wz * vy, force_y + kGravity * gy - wz * vx, wz * gy - wy * gz, wx * gz - wz * gx,
      0.0, 0.0;

  Matrix6d a = Matrix6d::Zero();
  a.row(0) << -slope_x, wz, kGravity, 0.0, 0.0, 0.0;
  a.row(1) << -wz, -slope_y, 0.0, kGravity, 0.0, 0.0;
  a.row(2) << 0.0, 0.0, wy * gx / gz, wz + wy * gy / gz, 0.0, gz;
  a.row(3) << 0.0, 0.0, -wz - wx * gx / gz, -wx * gy / gz, -gz, 0.0;
  if (windy_) {
    if (!held_force) {
      // d drag(v - w_b) / d gamma = slope * d w_b / d gamma: the tilt turns the wind into the body's axes.
      a.block<1, 2>(0, 2) -= a(0, 0) * wind_jacobian.row(0);
      a.block<1, 2>(1, 2) -= a(1, 1) * wind_jacobian.row(1);
    }
    // The ZYX yaw rate, (w_y sin(roll) + w_z cos(roll)) / cos(pitch), written with gamma.
    turn_heading(dt * (wy * gy + wz * gz) / (gy * gy + gz * gz));
  }

  x_ += x_dot * dt;
  const Matrix6d f = Matrix6d::Identity() + a * dt;
  p_ = f * p_ * f.transpose();
  p_.diagonal() += process_density_ * dt;
}

void DragVelocityEstimator::turn_heading(double angle) {
  // The heading is kept as its cosine and sine, which is all the wind's projection needs. One step turns it by
  // milliradians, where a short series is exact to 1e-16 and costs a fraction of std::cos and std::sin.
  double c, s;
  if (std::abs(angle) < 0.05) {
    const double a2 = angle * angle;
    c = 1.0 - a2 * (0.5 - a2 * (1.0 / 24.0));
    s = angle * (1.0 - a2 * (1.0 / 6.0 - a2 * (1.0 / 120.0)));
  } else {
    c = std::cos(angle);
    s = std::sin(angle);
  }
  const double new_cos = heading_cos_ * c - heading_sin_ * s;
  const double new_sin = heading_sin_ * c + heading_cos_ * s;
  const double unit = 0.5 * (3.0 - (new_cos * new_cos + new_sin * new_sin));  // one Newton step back to norm 1
  heading_cos_ = new_cos * unit;
  heading_sin_ = new_sin * unit;
}

Eigen::Vector2d DragVelocityEstimator::wind_in_body(Eigen::Matrix2d* jacobian) const {
  const double gx = x_[2], gy = x_[3];
  const double gz = std::sqrt(std::max(1.0 - gx * gx - gy * gy, kMinGammaZ * kMinGammaZ));
  const double c_pitch = std::sqrt(gy * gy + gz * gz);  // sin(pitch) = -gamma_x
  const double inv_c_pitch = 1.0 / c_pitch;
  // The wind in the yawed frame (x along the heading, y to its right), then through pitch and roll:
  //   R^T w = Rx(roll)^T Ry(pitch)^T (a, b, 0)  ->  (cos(pitch) a,  cos(roll) b + sin(roll) sin(pitch) a).
  const double c = heading_cos_, s = heading_sin_;
  const double a = c * params_.wind.x() + s * params_.wind.y();
  const double b = -s * params_.wind.x() + c * params_.wind.y();
  const double wy = (gz * b - gx * gy * a) * inv_c_pitch;
  if (jacobian) {
    // With gamma_z = sqrt(1 - gx^2 - gy^2) and cos(pitch) = sqrt(1 - gx^2).
    const double b_over_gz = b / gz;
    *jacobian << -gx * a * inv_c_pitch, 0.0, (-gx * b_over_gz - gy * a + wy * gx * inv_c_pitch) * inv_c_pitch,
        (-gy * b_over_gz - gx * a) * inv_c_pitch;
  }
  return {c_pitch * a, wy};
}

void DragVelocityEstimator::fuse_air_velocity(int axis, double air, double wind, const Eigen::Vector2d& jacobian) {
  const double predicted = x_[axis] - wind;
  const double slope = fusion_slope(axis, predicted);
  if (!(slope > 0.0)) return;
  const double r = config_.accel_noise * config_.accel_noise / (slope * slope);
  Vector6d h = Vector6d::Zero();
  h[axis] = 1.0;
  h.segment<2>(2) = -jacobian;
  const Vector6d ph = p_ * h;
  const Vector6d gain = ph / (h.dot(ph) + r);
  x_ += gain * (air - predicted);
  p_ -= gain * ph.transpose();
  p_ = (0.5 * (p_ + p_.transpose())).eval();
}

double DragVelocityEstimator::fusion_slope(int axis, double predicted) const {
  // The law's slope averaged over the prediction's spread (statistical linearisation): sqrt(E[slope^2]) for a velocity
  // of variance P about `predicted`. Taken at the prediction alone, a quadratic law has no slope at rest, and a filter
  // hovering there would never again listen to the accelerometer, though a reading near zero does say the speed is
  // small: |v| within sqrt(noise / mu).
  const double k = params_.drag_linear[axis], mu = params_.drag_quadratic[axis];
  const double at_prediction = drag_slope(k, mu, predicted);
  return std::sqrt(at_prediction * at_prediction + 4.0 * mu * mu * p_(axis, axis));
}

void DragVelocityEstimator::fuse_velocity(int axis, double v_measured) {
  // The inversion's noise is the accelerometer's divided by the law's slope, taken at the prediction rather than at
  // the noisy measurement. A zero slope (pure quadratic drag at rest) carries no information: skip.
  const double slope = fusion_slope(axis, x_[axis]);
  if (!(slope > 0.0)) return;
  update_velocity(axis, v_measured, config_.accel_noise * config_.accel_noise / (slope * slope));
}

void DragVelocityEstimator::update_velocity(int axis, double v_measured, double r) {
  const Vector6d gain = p_.col(axis) / (p_(axis, axis) + r);
  x_ += gain * (v_measured - x_[axis]);
  p_ -= gain * p_.row(axis);
  p_ = (0.5 * (p_ + p_.transpose())).eval();
}

}  // namespace imubridge::estimator
