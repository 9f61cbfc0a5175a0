#include "diagnose/model.hpp"

#include <ceres/ceres.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstring>
#include <exception>
#include <functional>
#include <limits>
#include <memory>
#include <numbers>
#include <optional>
#include <stdexcept>

#include "diagnose/live_model.hpp"
#include "diagnose/lowpass.hpp"
#include "estimator/constants.hpp"
#include "estimator/drag_law.hpp"
#include "estimator/full_model.hpp"
#include "estimator/velocity.hpp"
#include "identification/least_squares.hpp"
#include "identification/precise_solve.hpp"

namespace imubridge::diagnose {
namespace {

using Eigen::Quaterniond;
using Eigen::Vector3d;
using estimator::kGravity;

constexpr std::size_t kPaperParams = 4;  // r, beta, alpha, mu per axis

Eigen::Matrix3d rotation(const double* rotation_vector) {
  return rotation_matrix(Vector3d(rotation_vector[0], rotation_vector[1], rotation_vector[2]));
}

std::vector<Parameter> base_parameters(const ModelSetup& setup) {
  std::vector<Parameter> out;
  if (setup.base == ModelKind::paper) {
    for (int axis : setup.axes) {
      const std::string a = axis_name(axis) + ".";
      out.push_back({a + "r", "m", 0.0, 0.0, setup.lever_arm_bound});
      out.push_back({.name = a + "beta", .unit = "rad", .periodic = true});
      out.push_back({.name = a + "alpha", .unit = "rad", .periodic = true});
      out.push_back({a + "mu", "1/m", 0.0, 0.0, setup.drag_bound});
    }
  } else {
    for (int i = 0; i < 3; ++i)
      out.push_back({"lever_arm." + std::to_string(i), "m", 0.0, -setup.lever_arm_bound, setup.lever_arm_bound});
    for (int i = 0; i < 3; ++i) out.push_back({"mounting." + std::to_string(i), "rad"});
  }
  if (setup.velocity == VelocitySource::filter) {
    // The filter's process noise sets how fast its velocity follows the drag it measures; fitted with the model,
    // since a fixed wrong one biases the drag found (docs/identification.md). log10 of m/s^2/sqrt(Hz).
    out.push_back({std::string(Model::kProcessNoiseParameter), "log10(m/s^2/sqrt(Hz))",
                   std::log10(setup.filter.accel_process_noise), -3.0, 1.5});
  }
  return out;
}

estimator::PaperAxisParams paper_axis(std::span<const double> base, std::size_t i) {
  const double* p = base.data() + kPaperParams * i;
  return {p[0], p[1], p[2], p[3]};
}

// x(t - tau) by linear interpolation between samples, held at the ends.
template <typename Value>
std::vector<Value> delayed(std::span<const double> t, const std::vector<Value>& x, double tau) {
  std::vector<Value> out(x.size());
  std::size_t j = 0;
  for (std::size_t k = 0; k < t.size(); ++k) {
    const double at = t[k] - tau;
    if (at <= t.front()) {
      out[k] = x.front();
      continue;
    }
    if (at >= t.back()) {
      out[k] = x.back();
      continue;
    }
    while (j + 1 < t.size() && t[j + 1] < at) ++j;
    while (j > 0 && t[j] > at) --j;
    const double f = (at - t[j]) / (t[j + 1] - t[j]);
    out[k] = (1.0 - f) * x[j] + f * x[j + 1];
  }
  return out;
}

std::vector<Quaterniond> delayed(std::span<const double> t, const std::vector<Quaterniond>& q, double tau) {
  std::vector<Eigen::Vector4d> coeffs(q.size());
  for (std::size_t k = 0; k < q.size(); ++k) coeffs[k] = q[k].coeffs();
  const std::vector<Eigen::Vector4d> shifted = delayed(t, coeffs, tau);
  std::vector<Quaterniond> out(q.size());
  for (std::size_t k = 0; k < q.size(); ++k) out[k] = Quaterniond(shifted[k]).normalized();  // nlerp
  return out;
}

// One paper axis's eq. (12) with drag in the dynamics: v' = g sin(theta) - F(v_air), in the paper's sign
// (v = minus the body-axis velocity), F the body-axis drag specific force on the air velocity -v - w.
std::vector<double> integrate_paper_axis(std::span<const double> t, std::span<const double> theta, double k, double mu,
                                         double wind_body) {
  std::vector<double> v(t.size(), 0.0);
  const auto rate = [&](std::size_t i, double velocity) {
    return kGravity * std::sin(theta[i]) - estimator::drag_specific_force(k, mu, -velocity - wind_body);
  };
  for (std::size_t i = 1; i < t.size(); ++i) {
    const double dt = t[i] - t[i - 1];
    const double a0 = rate(i - 1, v[i - 1]);
    const double predicted = v[i - 1] + dt * a0;  // Heun: Euler predictor, trapezoidal corrector
    v[i] = v[i - 1] + 0.5 * dt * (a0 + rate(i, predicted));
  }
  return v;
}

// dead_reckon() with the horizontal drag law acting on the body-axis air velocity.
estimator::DeadReckoning dead_reckon_with_drag(std::span<const double> t, std::span<const Vector3d> gyro_body,
                                               std::span<const double> thrust, const DragLaw& law,
                                               const Vector3d& wind) {
  estimator::DeadReckoning out = estimator::dead_reckon(t, gyro_body, thrust);  // the attitude is drag-free
  const auto acceleration = [&](std::size_t i, const Vector3d& v_ned) {
    const Quaterniond& q = out.attitude[i];
    const Vector3d air = q.conjugate() * (v_ned - wind);
    const Vector3d drag(estimator::drag_specific_force(law.k.x(), law.mu.x(), air.x()),
                        estimator::drag_specific_force(law.k.y(), law.mu.y(), air.y()), 0.0);
    return Vector3d(q * (Vector3d(0.0, 0.0, -thrust[i]) + drag) + Vector3d(0.0, 0.0, kGravity));
  };
  for (std::size_t i = 1; i < t.size(); ++i) {
    const double dt = t[i] - t[i - 1];
    const Vector3d a0 = acceleration(i - 1, out.velocity_ned[i - 1]);
    const Vector3d predicted = out.velocity_ned[i - 1] + dt * a0;
    out.velocity_ned[i] = out.velocity_ned[i - 1] + 0.5 * dt * (a0 + acceleration(i, predicted));
  }
  return out;
}

}  // namespace

Range range_of(const Signals& s, const estimator::TimeWindow& w) {
  const auto first = std::lower_bound(s.t.begin(), s.t.end(), w.start);
  const auto last = std::lower_bound(first, s.t.end(), w.end);
  return {static_cast<std::size_t>(first - s.t.begin()), static_cast<std::size_t>(last - first)};
}

AxisValues Evaluation::residual() const {
  AxisValues out = measured;
  for (std::size_t i = 0; i < out.size(); ++i) {
    for (std::size_t k = 0; k < out[i].size(); ++k) out[i][k] -= predicted[i][k];
  }
  return out;
}

Model::Model(const Signals& signals, ModelSetup setup, std::vector<const Effect*> effects)
    : setup_(std::move(setup)), effects_(std::move(effects)) {
  setup_.signals = &signals;
  if (setup_.axes.empty()) throw std::invalid_argument("diagnose: no axis to diagnose");
  if (setup_.velocity == VelocitySource::reference && !signals.reference)
    throw std::invalid_argument("diagnose: velocity from the reference, but the session has no reference trajectory");
  parameters_ = base_parameters(setup_);
  base_size_ = parameters_.size();
  std::vector<std::string> before;
  for (const Effect* effect : effects_) {
    if (auto why = effect->why_not(setup_, before))
      throw std::invalid_argument("effect " + std::string(effect->name()) + " does not apply: " + *why);
    offsets_.push_back(parameters_.size());
    for (Parameter p : effect->parameters(setup_)) {
      // ModelSetup::held_at_zero: bounds that meet at zero hold it (inert).
      if (holds(setup_.held_at_zero, effect->name(), p.name)) p.initial = p.lower = p.upper = 0.0;
      parameters_.push_back(std::move(p));
    }
    before.emplace_back(effect->name());
  }
  offsets_.push_back(parameters_.size());

  // Which parameters stages 1-3 depend on: the mounting when the full model integrates the gyro in body axes, the
  // parameters of effects acting there, and every drag coefficient once drag is in the dynamics.
  input_parameter_.assign(parameters_.size(), false);
  const bool drag_in_dynamics =
      std::any_of(effects_.begin(), effects_.end(), [](const Effect* e) { return e->stages().drag_in_dynamics; });
  if (filter_runs()) {
    // The filter runs the whole model: every parameter moves its velocity.
    input_parameter_.assign(parameters_.size(), true);
  }
  if (setup_.base == ModelKind::full && setup_.velocity == VelocitySource::eq12) {
    for (std::size_t i = 3; i < 6; ++i) input_parameter_[i] = true;
  }
  if (setup_.base == ModelKind::paper && drag_in_dynamics) {
    for (std::size_t i = 0; i < setup_.axes.size(); ++i) input_parameter_[kPaperParams * i + 3] = true;
  }
  for (std::size_t e = 0; e < effects_.size(); ++e) {
    if (effects_[e]->changes_inputs() || (drag_in_dynamics && effects_[e]->adds_drag())) {
      for (std::size_t i = offsets_[e]; i < offsets_[e + 1]; ++i) input_parameter_[i] = true;
    }
  }
  if (std::none_of(input_parameter_.begin(), input_parameter_.end(), [](bool b) { return b; })) {
    bool plain_gyro = false;
    compute_inputs(std::vector<double>(parameters_.size(), 0.0), signals.size(), fixed_inputs_.emplace(), plain_gyro);
  }
}

const ModelInputs& Model::inputs_for(std::span<const double> p, std::size_t until) const {
  if (fixed_inputs_) return *fixed_inputs_;
  std::vector<double> key;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (input_parameter_[i]) key.push_back(p[i]);
  }
  if (!cached_inputs_ || key != cached_key_ || cached_until_ < until) {
    // Refilled in place: the vectors keep their memory. A flight's worth of fresh pages for every evaluation of a
    // Jacobian cost more than some of the evaluation itself.
    ModelInputs& in = cached_inputs_ ? *cached_inputs_ : cached_inputs_.emplace();
    try {
      compute_inputs(p, until, in, cached_plain_gyro_);
    } catch (...) {
      cached_inputs_.reset();  // half refilled: no longer the inputs of cached_key_
      cached_plain_gyro_ = false;
      throw;
    }
    cached_key_ = std::move(key);
    cached_until_ = until;
  }
  return *cached_inputs_;
}

ModelInputs Model::inputs(std::span<const double> p) const { return inputs_for(p, signals().size()); }

double Model::gyro_inputs(std::span<const double> p, ModelInputs& in, bool& plain_gyro) const {
  const Signals& s = signals();
  const auto params_of = [&](std::size_t i) { return p.subspan(offsets_[i], offsets_[i + 1] - offsets_[i]); };
  // 2. timing: the accelerometer's sample at t saw the motion of t - tau.
  double tau = 0.0;
  for (std::size_t i = 0; i < effects_.size(); ++i) {
    if (effects_[i]->stages().timing) tau += effects_[i]->time_offset(params_of(i));
  }
  // 1. gyro, then 2.'s shift. Unchanged, the signals' own gyro is not copied again into inputs that hold it.
  const bool gyro_effects =
      std::any_of(effects_.begin(), effects_.end(), [](const Effect* e) { return e->stages().gyro; });
  if (gyro_effects || tau != 0.0 || !plain_gyro) {
    plain_gyro = false;
    in.gyro = s.gyro;
    for (std::size_t i = 0; i < effects_.size(); ++i) {
      if (effects_[i]->stages().gyro) effects_[i]->adjust_gyro(params_of(i), setup_, in.gyro);
    }
    in.gyro_rate = s.gyro_rate;
    if (tau != 0.0) {
      in.gyro = delayed(std::span<const double>(s.t), in.gyro, tau);
      in.gyro_rate = delayed(std::span<const double>(s.t), in.gyro_rate, tau);
    }
  }
  plain_gyro = !gyro_effects && tau == 0.0;
  return tau;
}

void Model::compute_inputs(std::span<const double> p, std::size_t until, ModelInputs& in, bool& plain_gyro) const {
  const Signals& s = signals();
  const std::span<const double> t = s.t;
  const std::size_t n = s.size();
  const auto params_of = [&](std::size_t i) { return p.subspan(offsets_[i], offsets_[i + 1] - offsets_[i]); };
  in.attitude.clear();                                // set below where the velocity source has one
  const double tau = gyro_inputs(p, in, plain_gyro);  // stages 1 and 2

  // 3. velocity: the drag law of the base model and the effects, the wind, and drag in the dynamics or not.
  DragLaw law;
  if (setup_.base == ModelKind::paper) {
    for (std::size_t i = 0; i < setup_.axes.size(); ++i) law.mu[setup_.axes[i]] = p[kPaperParams * i + 3];
  }
  Vector3d wind = Vector3d::Zero();
  bool drag_in_dynamics = false, measured_thrust = false;
  for (std::size_t i = 0; i < effects_.size(); ++i) {
    const Stages stages = effects_[i]->stages();
    if (stages.drag) effects_[i]->add_drag(params_of(i), setup_, law);
    if (stages.wind) wind += effects_[i]->wind_ned(params_of(i));
    drag_in_dynamics = drag_in_dynamics || stages.drag_in_dynamics;
    measured_thrust = measured_thrust || stages.measured_thrust;
  }
  // The same for every parameter: filled once into reused inputs.
  if (in.thrust.size() != n) {
    if (measured_thrust)
      in.thrust = s.thrust;
    else
      in.thrust.assign(n, kGravity);
  }

  if (setup_.velocity == VelocitySource::filter) {
    // Without drag the filter has nothing to fuse, and nothing in the model reads a velocity.
    if (filter_runs())
      filter_velocity(p, until, in.velocity);
    else
      in.velocity.assign(n, Vector3d::Zero());
    return;  // already the air velocity, in the filter's body axes
  }
  if (setup_.velocity == VelocitySource::reference) {
    in.velocity = s.reference->velocity_body;
    in.attitude = s.reference->attitude;
    if (tau != 0.0) {
      in.velocity = delayed(t, in.velocity, tau);
      in.attitude = delayed(t, in.attitude, tau);
    }
  } else if (setup_.base == ModelKind::paper) {
    // Eq. (11)-(12) per axis; the roll axis is the pitch model turned 90 deg about z_b (omega' = -omega_x).
    std::vector<double> pitch_rate(n), roll_rate(n);
    for (std::size_t k = 0; k < n; ++k) pitch_rate[k] = in.gyro[k].y(), roll_rate[k] = -in.gyro[k].x();
    const estimator::PitchIntegration pitch = estimator::integrate_pitch(t, pitch_rate);
    const estimator::PitchIntegration roll = estimator::integrate_pitch(t, roll_rate);
    std::vector<double> v_pitch = pitch.v, v_roll = roll.v;
    if (drag_in_dynamics) {
      // With the yaw held, body axes x and y point north and east to first order.
      v_pitch = integrate_paper_axis(t, pitch.theta, law.k.x(), law.mu.x(), wind.x());
      v_roll = integrate_paper_axis(t, roll.theta, law.k.y(), law.mu.y(), wind.y());
    }
    in.velocity.resize(n);
    in.attitude.resize(n);
    for (std::size_t k = 0; k < n; ++k) {
      in.velocity[k] = {-v_pitch[k], -v_roll[k], 0.0};
      in.attitude[k] =
          Eigen::AngleAxisd(pitch.theta[k], Vector3d::UnitY()) * Eigen::AngleAxisd(-roll.theta[k], Vector3d::UnitX());
    }
  } else {
    // The 3-D generalisation: the gyro turned into body axes by the mounting being fitted.
    const Eigen::Matrix3d imu_to_body = rotation(p.data() + 3);
    std::vector<Vector3d> gyro_body(n);
    for (std::size_t k = 0; k < n; ++k) gyro_body[k] = imu_to_body * in.gyro[k];
    const std::vector<double> g(n, kGravity);
    const estimator::DeadReckoning dr =
        drag_in_dynamics ? dead_reckon_with_drag(t, gyro_body, g, law, wind) : estimator::dead_reckon(t, gyro_body, g);
    in.attitude = dr.attitude;
    in.velocity = estimator::body_velocity(dr.attitude, dr.velocity_ned);
  }
  if (!wind.isZero()) {
    for (std::size_t k = 0; k < n; ++k) in.velocity[k] -= in.attitude[k].conjugate() * wind;
  }
}

double Model::process_noise(std::span<const double> p) const {
  if (setup_.velocity != VelocitySource::filter) return setup_.filter.accel_process_noise;
  return std::pow(10.0, p[base_size_ - 1]);
}

bool Model::inert(std::size_t i) const {
  // A parameter whose bounds meet is held there (the base's lever arm at the mass centre, when the data cannot place
  // it inside the plausibility table).
  if (parameters_[i].lower == parameters_[i].upper) return true;
  return setup_.velocity == VelocitySource::filter && !filter_runs() && i + 1 == base_size_;
}

std::string Model::inert_reason(std::size_t i) const {
  if (!inert(i)) return "";
  // An effect's parameter has no bounds that meet but those ModelSetup::held_at_zero gives it.
  if (i >= base_size_ && parameters_[i].lower == parameters_[i].upper)
    return "held at 0: its fit went past the plausibility table";
  if (parameters_[i].lower == parameters_[i].upper) return "held at the only value its bounds allow";
  return "held: nothing depends on it until a drag gives the filter something to fuse";
}

bool Model::filter_runs() const {
  return setup_.velocity == VelocitySource::filter &&
         (setup_.base == ModelKind::paper ||
          std::any_of(effects_.begin(), effects_.end(), [](const Effect* e) { return e->adds_drag(); }));
}

std::vector<Vector3d> Model::accel_without_lever_arm(const estimator::FullModelParams& params,
                                                     std::span<const Vector3d> gyro, std::size_t count) const {
  const Signals& s = signals();
  std::vector<Vector3d> gyro_rate_shifted;
  if (params.time_offset != 0.0) gyro_rate_shifted = delayed(s.t, s.gyro_rate, params.time_offset);
  const std::span<const Vector3d> gyro_rate =
      gyro_rate_shifted.empty() ? std::span<const Vector3d>(s.gyro_rate) : gyro_rate_shifted;
  const Eigen::Matrix3d imu_to_body = rotation_matrix(params.mounting);
  // LeverArmCompensator's f = R_bs S^-1 (m - b) - L with L taken out of m instead: m - S R_bs^T L.
  const Eigen::Matrix3d body_to_reading = estimator::sensor_matrix(params) * imu_to_body.transpose();
  const Vector3d& r = params.lever_arm;
  std::vector<Vector3d> accel(count);
  for (std::size_t k = 0; k < count; ++k) {
    const Vector3d w = imu_to_body * (gyro[k] - params.gyro_bias);
    const Vector3d w_dot = imu_to_body * gyro_rate[k];
    accel[k] = s.accel[k] - body_to_reading * (w_dot.cross(r) + w.cross(w.cross(r)));
  }
  return accel;
}

void Model::filter_velocity(std::span<const double> p, std::size_t until, std::vector<Vector3d>& velocity) const {
  const Signals& s = signals();
  // The model as the live estimator runs it (effects it cannot run, such as vibration, act after stage 3 only).
  estimator::FullModelParams params = live_params(*this, p).full;
  // The time offset shifts the gyro here, as stage 2 does, rather than in the filter's aligner: that one starts the
  // filter |tau| late, a jump between tau = 0 and any other value that no derivative could step across.
  std::vector<Vector3d> shifted;
  if (params.time_offset != 0.0) shifted = delayed(s.t, s.gyro, params.time_offset);
  const std::span<const Vector3d> gyro = shifted.empty() ? std::span<const Vector3d>(s.gyro) : shifted;
  // The lever arm's reading is taken out at the full rate, where the smoothed derivative follows the manoeuvres, and
  // the filter runs without one. On block means its own differentiator spans five blocks (160 ms at 25 Hz) and misses
  // an agile flight's angular acceleration: the filter read the lever arm's r * w_dot as drag (docs/effects.md).
  estimator::FullModelParams filtered = params;
  filtered.lever_arm.setZero();
  filtered.time_offset = 0.0;
  estimator::DragVelocityConfig config = setup_.filter;
  config.accel_process_noise = process_noise(p);
  estimator::DragVelocityEstimator filter(filtered, config);
  const std::size_t block = setup_.filter_block;
  const std::size_t delay = static_cast<std::size_t>(filter.delay_samples());
  // Block j's estimate comes delay_samples() blocks after it.
  const std::size_t blocks = until == 0 ? 0 : std::min(s.size() / block, (until - 1) / block + 1 + delay);
  const bool lever = params.lever_arm != Vector3d::Zero();
  const auto means_of = [&] {
    return lever ? block_means(s.t, gyro, accel_without_lever_arm(params, gyro, blocks * block), block, blocks)
                 : block_means(s.t, gyro, s.accel, block, blocks);
  };
  std::vector<estimator::ImuSample> shifted_means;
  if (!shifted.empty()) {
    shifted_means = means_of();
  } else {
    // Without a time offset the block means depend only on what makes the lever arm's reading, the same for most of
    // a numeric Jacobian's evaluations (the drag's, the process noise's): kept with the values they were made for,
    // the longest run asked for (a block's mean does not depend on how many are taken).
    std::vector<double> key;
    if (lever) {
      for (const Vector3d* v : {&params.lever_arm, &params.mounting, &params.accel_scale, &params.gyro_bias})
        key.insert(key.end(), v->data(), v->data() + 3);
      key.insert(key.end(), params.accel_cross.data(), params.accel_cross.data() + 9);
    }
    if (key != block_means_key_ || block_means_.size() < blocks) {
      block_means_ = means_of();
      block_means_key_ = std::move(key);
    }
  }
  const std::span<const estimator::ImuSample> means =
      shifted.empty() ? std::span<const estimator::ImuSample>(block_means_).first(blocks) : shifted_means;
  velocity.resize(s.size());  // every sample is written below: those before `until` here, the rest zeroed at the end
  // Every sample of block j takes the prediction for block j, made from the blocks before it; samples the filter
  // holds no estimate for (the first blocks, those a time offset's aligner waits on) keep the last prediction.
  std::size_t filled = 0;
  const auto hold_until = [&](std::size_t end) {
    for (; filled < end; ++filled) velocity[filled] = filled == 0 ? Vector3d::Zero() : velocity[filled - 1];
  };
  for (std::size_t j = 0; j < means.size(); ++j) {
    const std::optional<estimator::DragVelocityEstimate> e = filter.update(means[j]);
    if (!e || j < delay) continue;
    const std::size_t first = (j - delay) * block;
    hold_until(first);
    Vector3d v(e->prior_air_velocity.x(), e->prior_air_velocity.y(), 0.0);
    // A filter driven out of its range (a diverging candidate) gives no velocity: the fit sees a failed evaluation.
    if (!v.allFinite()) v.setConstant(std::numeric_limits<double>::quiet_NaN());
    for (std::size_t k = first; k < first + block; ++k) velocity[k] = v;
    filled = first + block;
  }
  hold_until(std::min(until, s.size()));
  std::fill(velocity.begin() + static_cast<std::ptrdiff_t>(filled), velocity.end(), Vector3d::Zero());
}

Evaluation Model::evaluate(std::span<const double> p, Range range) const {
  Evaluation e;
  evaluate_into(p, range, e);
  return e;
}

void Model::predict_base(std::span<const double> p, Range range, const DragLaw& effect_drag, PredictionContext& ctx,
                         std::vector<Vector3d>& predicted) const {
  const ModelInputs& in = ctx.inputs;
  if (setup_.base == ModelKind::paper) {
    for (std::size_t i = 0; i < setup_.axes.size(); ++i) {
      const int axis = setup_.axes[i];
      const bool pitch = axis == 0;
      const estimator::PaperAxisParams params = paper_axis(p, i);
      ctx.paper.push_back(params);
      const estimator::PaperCoefficients<double> c = estimator::paper_coefficients(params);
      const double sin_alpha = std::sin(params.alpha);
      for (std::size_t k = 0; k < range.count; ++k) {
        const std::size_t j = range.first + k;
        const estimator::PaperSample sample{.t = signals().t[j],
                                            .omega = pitch ? in.gyro[j].y() : -in.gyro[j].x(),
                                            .omega_dot = pitch ? in.gyro_rate[j].y() : -in.gyro_rate[j].x(),
                                            .v = -in.velocity[j][axis]};
        // Eq. (14) takes U1 = g; with the thrust effect it is the measured T.
        predicted[k][axis] =
            estimator::paper_specific_force(c, sample) + (in.thrust[j] - kGravity) * sin_alpha +
            estimator::drag_specific_force(effect_drag.k[axis], effect_drag.mu[axis], in.velocity[j][axis]);
      }
    }
    return;
  }
  estimator::FullModelParams full;
  full.lever_arm = Vector3d(p[0], p[1], p[2]);
  full.mounting = Vector3d(p[3], p[4], p[5]);
  full.drag_linear = effect_drag.k;
  full.drag_quadratic = effect_drag.mu;
  ctx.imu_to_body = rotation(p.data() + 3);
  for (std::size_t k = 0; k < range.count; ++k) {
    const std::size_t j = range.first + k;
    predicted[k] = estimator::predict_specific_force(full, ctx.imu_to_body,
                                                     {.gyro = in.gyro[j],
                                                      .gyro_rate = in.gyro_rate[j],
                                                      .velocity = in.velocity[j].head<2>(),
                                                      .thrust = in.thrust[j]});
  }
}

void Model::evaluate_into(std::span<const double> p, Range range, Evaluation& e) const {
  if (p.size() != parameters_.size()) throw std::invalid_argument("Model::evaluate: wrong number of parameters");
  if (range.first + range.count > signals().size()) throw std::invalid_argument("Model::evaluate: range too long");
  const ModelInputs& in = inputs_for(p, range.first + range.count);
  const auto params_of = [&](std::size_t i) { return p.subspan(offsets_[i], offsets_[i + 1] - offsets_[i]); };
  const std::size_t axes = setup_.axes.size();

  const std::span<const Vector3d> measured(signals().accel.data() + range.first, range.count);
  // The effects' own drag (the paper's mu is inside eq. 14).
  DragLaw effect_drag;
  for (std::size_t i = 0; i < effects_.size(); ++i) {
    if (effects_[i]->adds_drag()) effects_[i]->add_drag(params_of(i), setup_, effect_drag);
  }

  // The base model's predicted reading in IMU axes (the paper model fills the axes it diagnoses).
  std::vector<Vector3d>& predicted = predicted_scratch_;
  predicted.assign(range.count, Vector3d::Zero());
  PredictionContext ctx{setup_, in, {}, Eigen::Matrix3d::Identity(), range.first, range.count};
  predict_base(p, range, effect_drag, ctx, predicted);
  // 4. sensor
  for (std::size_t i = 0; i < effects_.size(); ++i) {
    if (effects_[i]->stages().sensor) effects_[i]->adjust_sensor(params_of(i), setup_, predicted, measured);
  }

  // In the residual's frame: the paper model's sensor axes; the full model's body axes, where the thrust (unknown
  // per sample) only has a z component, so rows x and y. Every value is written below: no need to clear them.
  for (AxisValues* values : {&e.measured, &e.predicted}) {
    values->resize(axes);
    for (std::vector<double>& axis : *values) axis.resize(range.count);
  }
  // The band limit: both sides alike, so the residual is the model's error inside the band. The filter is linear, so
  // the measurement is low-passed once per range, in IMU axes, and rotated after.
  const std::span<const Vector3d> compared = setup_.lowpass_hz > 0.0 ? lowpassed_measurement(range) : measured;
  for (std::size_t k = 0; k < range.count; ++k) {
    const Vector3d m = setup_.base == ModelKind::paper ? compared[k] : Vector3d(ctx.imu_to_body * compared[k]);
    const Vector3d f = setup_.base == ModelKind::paper ? predicted[k] : Vector3d(ctx.imu_to_body * predicted[k]);
    for (std::size_t i = 0; i < axes; ++i) {
      e.measured[i][k] = m[setup_.axes[i]];
      e.predicted[i][k] = f[setup_.axes[i]];
    }
  }
  // 5. prediction
  for (std::size_t i = 0; i < effects_.size(); ++i) {
    if (effects_[i]->stages().prediction) effects_[i]->add_prediction(params_of(i), ctx, e.predicted);
  }
  if (setup_.lowpass_hz > 0.0) {
    for (std::size_t i = 0; i < axes; ++i) zero_phase_lowpass(e.predicted[i], setup_.lowpass_hz, signals().rate_hz);
  }
}

std::span<const Vector3d> Model::lowpassed_measurement(Range range) const {
  for (const auto& [cached, values] : lowpassed_) {
    if (cached.first == range.first && cached.count == range.count) return values;
  }
  std::vector<Vector3d> values(range.count);
  for (int axis = 0; axis < 3; ++axis) {
    std::vector<double> x(range.count);
    for (std::size_t k = 0; k < range.count; ++k) x[k] = signals().accel[range.first + k][axis];
    zero_phase_lowpass(x, setup_.lowpass_hz, signals().rate_hz);
    for (std::size_t k = 0; k < range.count; ++k) values[k][axis] = x[k];
  }
  lowpassed_.emplace_back(range, std::move(values));
  return lowpassed_.back().second;
}

void Model::residuals(std::span<const double> p, Range range, double* out) const {
  Evaluation& e = residual_scratch_;
  evaluate_into(p, range, e);
  const std::size_t axes = e.measured.size();
  for (std::size_t k = 0; k < range.count; ++k) {
    for (std::size_t i = 0; i < axes; ++i) out[k * axes + i] = e.measured[i][k] - e.predicted[i][k];
  }
}

double Model::rmse(std::span<const double> p, Range range) const {
  if (range.count == 0) return 0.0;
  std::vector<double> r(range.count * setup_.axes.size());
  residuals(p, range, r.data());
  double sum = 0.0;
  for (double x : r) sum += x * x;
  return std::sqrt(sum / static_cast<double>(r.size()));
}

std::vector<double> Model::base_start(Range range) const {
  std::vector<double> p(parameters_.size());
  for (std::size_t i = 0; i < p.size(); ++i) p[i] = parameters_[i].initial;
  if (setup_.base == ModelKind::full) {
    for (int i = 0; i < 3; ++i) p[3 + i] = signals().level_mounting[i];
    return {p.begin(), p.begin() + static_cast<std::ptrdiff_t>(base_size_)};
  }
  if (setup_.velocity == VelocitySource::filter) {
    // The filter's velocity needs a drag to fuse: the paper's mu, from its decades, before the linear fit.
    std::vector<std::size_t> mu;
    for (std::size_t i = 0; i < setup_.axes.size(); ++i) mu.push_back(kPaperParams * i + 3);
    scan_drag_start(p, mu, range);
  }
  // Eq. (14) is linear in its four combinations: their least-squares fit is the optimum of the base alone.
  const ModelInputs in = inputs(p);
  for (std::size_t i = 0; i < setup_.axes.size(); ++i) {
    const int axis = setup_.axes[i];
    const bool pitch = axis == 0;
    std::vector<estimator::PaperSample> samples(range.count);
    for (std::size_t k = 0; k < range.count; ++k) {
      const std::size_t j = range.first + k;
      samples[k] = {.t = signals().t[j],
                    .omega = pitch ? in.gyro[j].y() : -in.gyro[j].x(),
                    .omega_dot = pitch ? in.gyro_rate[j].y() : -in.gyro_rate[j].x(),
                    .v = -in.velocity[j][axis],
                    .f = signals().accel[j][axis]};
    }
    estimator::PaperAxisParams start;
    start.mu = p[kPaperParams * i + 3];
    try {
      start = estimator::paper_linear_fit(samples);
      // The filter fuses nothing without drag: keep the scanned one when the linear fit finds none.
      if (setup_.velocity == VelocitySource::filter && !(start.mu > 0.0)) start.mu = p[kPaperParams * i + 3];
    } catch (const std::invalid_argument&) {
      // Data that do not determine all four terms (no motion): LM starts from the precise installation.
    }
    p[kPaperParams * i] = start.r;
    p[kPaperParams * i + 1] = start.beta;
    p[kPaperParams * i + 2] = start.alpha;
    p[kPaperParams * i + 3] = start.mu;
  }
  return {p.begin(), p.begin() + static_cast<std::ptrdiff_t>(base_size_)};
}

void Model::scan_drag_start(std::vector<double>& p, std::span<const std::size_t> indices, Range range,
                            unsigned threads) const {
  constexpr std::size_t kStarts = std::size(kDragStarts);
  std::array<double, kStarts> rmses{};
  std::array<std::exception_ptr, kStarts> failed{};
  // Each value's RMSE is its own filter run: the threads take the next value when free, each on a model of its own
  // (a model's caches are not shared between threads), and the lowest is chosen in the values' order after (the
  // first value's failure thrown, as one thread would).
  std::atomic<std::size_t> next{0};
  const auto work = [&](const Model& model) {
    std::vector<double> trial = p;
    for (std::size_t v = next++; v < kStarts; v = next++) {
      for (std::size_t i : indices) trial[i] = std::clamp(kDragStarts[v], parameters_[i].lower, parameters_[i].upper);
      try {
        rmses[v] = model.rmse(trial, range);
      } catch (...) {
        failed[v] = std::current_exception();
      }
    }
  };
  const std::size_t workers = std::min<std::size_t>(std::max(1u, threads), kStarts);
  std::vector<std::unique_ptr<Model>> others;
  for (std::size_t t = 1; t < workers; ++t) others.push_back(std::make_unique<Model>(signals(), setup(), effects()));
  estimator::on_threads(workers, [&](std::size_t w) { work(w == 0 ? *this : *others[w - 1]); });
  double best_rmse = std::numeric_limits<double>::infinity(), best = p.empty() ? 0.0 : p[indices.front()];
  for (std::size_t v = 0; v < kStarts; ++v) {
    if (failed[v]) std::rethrow_exception(failed[v]);
    if (rmses[v] < best_rmse) best_rmse = rmses[v], best = kDragStarts[v];
  }
  for (std::size_t i : indices) p[i] = std::clamp(best, parameters_[i].lower, parameters_[i].upper);
}

namespace {

struct ModelCost {
  const Model* model;
  Range range;
  bool operator()(double const* const* parameters, double* residuals) const {
    model->residuals({parameters[0], model->parameters().size()}, range, residuals);
    // A non-finite residual (a filter that diverged at these values) fails the evaluation: LM shortens its step.
    return std::all_of(residuals, residuals + range.count * model->setup().axes.size(),
                       [](double r) { return std::isfinite(r); });
  }
};

// The model's residuals on `range` as one Ceres cost with a central-difference Jacobian.
ceres::CostFunction* central_difference_cost(const Model& model, Range range, std::size_t parameters,
                                             std::size_t residuals) {
  auto* cost = new ceres::DynamicNumericDiffCostFunction<ModelCost, ceres::CENTRAL>(new ModelCost{&model, range});
  cost->AddParameterBlock(static_cast<int>(parameters));
  cost->SetNumResiduals(static_cast<int>(residuals));
  return cost;
}

// Forward differences for a model whose every evaluation runs the filter over the flight, the Jacobian's columns
// shared among `threads` threads, each on a model of its own (a model's caches are not shared between threads).
// Each column is Ceres' own forward difference (numeric_diff.h: a step of 1e-6 of the value, at least sqrt(epsilon);
// (r(x + h) - r(x)) * (1 / h)), so the fit is bit for bit the same on any number of threads.
class ForwardDifferenceCost final : public ceres::CostFunction {
 public:
  ForwardDifferenceCost(const Model& model, Range range, std::size_t parameters, std::size_t residuals,
                        unsigned threads)
      : range_(range), parameters_(parameters), residuals_(residuals), columns_(parameters * residuals) {
    models_.push_back(&model);
    for (unsigned t = 1; t < std::max(1u, threads); ++t) {
      own_.push_back(std::make_unique<Model>(model.signals(), model.setup(), model.effects()));
      models_.push_back(own_.back().get());
    }
    mutable_parameter_block_sizes()->push_back(static_cast<std::int32_t>(parameters));
    set_num_residuals(static_cast<int>(residuals));
  }

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    if (jacobians == nullptr || jacobians[0] == nullptr)
      return ModelCost{models_.front(), range_}(parameters, residuals);
    const double* x = parameters[0];
    double* jacobian = jacobians[0];  // row-major: residual i, parameter j at i * parameters + j
    // r(x) is one more task beside the columns' r(x + h) (each kept in columns_ until r(x) is known), so that the
    // threads share parameters + 1 evaluations instead of all waiting for r(x) first. Each takes the next task when
    // it is free, so a core another process slows takes fewer; a task's result does not depend on which thread ran it.
    // A task that throws or fails (a non-finite residual) stops the others; r(x)'s failure counts first, as when it
    // was evaluated before the columns.
    std::atomic<bool> going{true};
    std::atomic<std::size_t> next{0};
    std::vector<char> finite(parameters_ + 1, 1);
    std::vector<std::exception_ptr> thrown(parameters_ + 1);
    const auto tasks = [&](std::size_t worker) {
      std::vector<double> shifted(x, x + parameters_);
      const double* shifted_blocks[] = {shifted.data()};
      const ModelCost cost{models_[worker], range_};
      for (std::size_t task = next++; task <= parameters_ && going; task = next++) {
        const std::size_t j = task - 1;  // the column; task 0 is r(x)
        try {
          if (task > 0) shifted[j] = x[j] + step(x[j]);
          finite[task] = task == 0 ? cost(parameters, residuals) : cost(shifted_blocks, &columns_[j * residuals_]);
        } catch (...) {
          thrown[task] = std::current_exception();
        }
        if (!finite[task] || thrown[task]) going = false;
        if (task > 0) shifted[j] = x[j];
      }
    };
    estimator::on_threads(models_.size(), tasks);
    if (thrown[0]) std::rethrow_exception(thrown[0]);
    if (!finite[0]) return false;
    for (const std::exception_ptr& e : thrown) {
      if (e) std::rethrow_exception(e);
    }
    if (std::find(finite.begin(), finite.end(), 0) != finite.end()) return false;
    std::vector<double> one_over_step(parameters_);
    for (std::size_t j = 0; j < parameters_; ++j) one_over_step[j] = 1.0 / step(x[j]);
    for (std::size_t i = 0; i < residuals_; ++i) {
      double* row = jacobian + i * parameters_;
      for (std::size_t j = 0; j < parameters_; ++j)
        row[j] = (columns_[j * residuals_ + i] - residuals[i]) * one_over_step[j];
    }
    return true;
  }

 private:
  static double step(double x) {
    return std::max(std::sqrt(std::numeric_limits<double>::epsilon()), std::abs(x) * 1e-6);
  }

  Range range_;
  std::size_t parameters_, residuals_;
  mutable std::vector<double> columns_;  // r(x + h) of column j at j * residuals_, kept between evaluations
  std::vector<std::unique_ptr<Model>> own_;
  std::vector<const Model*> models_;  // the caller's first
};

// Ceres evaluates a bounded problem's points more than once: LM's projected line search takes the gradient (so the
// Jacobian) at the candidate, the candidate's cost is evaluated again, and a successful step evaluates the Jacobian
// there once more (trust_region_minimizer.cc); the covariance and the precision check evaluate the final point again.
// A model's residuals are a deterministic function of the parameters, so the last point's residuals and Jacobian are
// handed back, bit for bit what evaluating again would give, when the same parameters (to the bit) come back.
// Single-threaded, as the solver runs it (num_threads 1).
class LastPointCache final : public ceres::CostFunction {
 public:
  explicit LastPointCache(ceres::CostFunction* inner) : inner_(inner) {
    *mutable_parameter_block_sizes() = inner->parameter_block_sizes();
    set_num_residuals(inner->num_residuals());
  }

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    const std::size_t n = static_cast<std::size_t>(parameter_block_sizes().front());
    const std::size_t m = static_cast<std::size_t>(num_residuals());
    const bool want_jacobian = jacobians != nullptr && jacobians[0] != nullptr;
    const bool same = x_.size() == n && std::memcmp(x_.data(), parameters[0], n * sizeof(double)) == 0;
    if (same && (jacobian_.size() == m * n || !want_jacobian)) {
      std::copy(residuals_.begin(), residuals_.end(), residuals);
      if (want_jacobian) std::copy(jacobian_.begin(), jacobian_.end(), jacobians[0]);
      return true;
    }
    x_.clear();
    if (!inner_->Evaluate(parameters, residuals, jacobians)) return false;
    x_.assign(parameters[0], parameters[0] + n);
    residuals_.assign(residuals, residuals + m);
    if (want_jacobian)
      jacobian_.assign(jacobians[0], jacobians[0] + m * n);
    else
      jacobian_.clear();
    return true;
  }

 private:
  std::unique_ptr<ceres::CostFunction> inner_;
  mutable std::vector<double> x_, residuals_, jacobian_;  // x_ empty: nothing kept
};

class RecordCost final : public ceres::IterationCallback {
 public:
  explicit RecordCost(std::vector<double>& costs) : costs_(costs) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override {
    if (summary.step_is_successful || summary.iteration == 0) costs_.push_back(std::sqrt(2.0 * summary.cost));
    return ceres::SOLVER_CONTINUE;
  }

 private:
  std::vector<double>& costs_;
};

// The parameters the fit left on one of their bounds (an inert one excepted: it is held anyway).
std::vector<std::size_t> on_bound(const Model& model, std::span<const double> x) {
  std::vector<std::size_t> pinned;
  for (std::size_t i = 0; i < x.size(); ++i) {
    const Parameter& p = model.parameters()[i];
    if (!model.inert(i) && (x[i] <= p.lower || x[i] >= p.upper)) pinned.push_back(i);
  }
  return pinned;
}

// Standard errors: (J^T J)^-1 scaled by the residual variance (identification/least_squares.cpp does the same), at
// out.values, the problem's one parameter block.
void standard_errors(ceres::Problem& problem, const Model& model, std::size_t residual_count, FitOutcome& out) {
  const std::vector<Parameter>& params = model.parameters();
  double* x = out.values.data();
  out.std_errors.assign(params.size(), std::numeric_limits<double>::quiet_NaN());
  double final_cost = 0.0;
  problem.Evaluate(ceres::Problem::EvaluateOptions(), &final_cost, nullptr, nullptr, nullptr);
  const double variance = 2.0 * final_cost / static_cast<double>(residual_count - params.size());
  ceres::Covariance::Options covariance_options;
  covariance_options.algorithm_type = ceres::DENSE_SVD;
  covariance_options.num_threads = 1;
  ceres::Covariance covariance(covariance_options);
  const std::vector<const double*> blocks{x};
  std::optional<Eigen::MatrixXd> c;
  std::vector<std::size_t> held_on_bound;
  const auto held = [&](std::size_t i) {
    return model.inert(i) || std::find(held_on_bound.begin(), held_on_bound.end(), i) != held_on_bound.end();
  };
  if (covariance.Compute(blocks, &problem)) {
    c.emplace(params.size(), params.size());
    covariance.GetCovarianceBlock(x, x, c->data());  // symmetric: storage order does not matter
  } else if (held_on_bound = on_bound(model, out.values); !held_on_bound.empty()) {
    // A parameter on its bound can move nothing there (the filter's process noise on its floor): its zero column
    // makes the whole covariance singular, and every other standard error unknown, though the data determine them.
    // Held there with the inert ones, it leaves the others' computable.
    std::vector<int> constant;
    for (std::size_t i = 0; i < params.size(); ++i) {
      if (held(i)) constant.push_back(static_cast<int>(i));
    }
    problem.SetManifold(x, new ceres::SubsetManifold(static_cast<int>(params.size()), constant));
    ceres::Covariance without(covariance_options);
    if (without.Compute(blocks, &problem)) {
      c.emplace(params.size(), params.size());
      without.GetCovarianceBlock(x, x, c->data());
    }
  }
  if (!c) {
    out.covariance_failure = "the Jacobian is rank-deficient: some parameters cannot be told apart with these data";
    return;
  }
  for (std::size_t i = 0; i < params.size(); ++i) {
    if (!held(i))
      out.std_errors[i] = std::sqrt(variance * (*c)(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(i)));
  }
  const Eigen::VectorXd inverse_sd = c->diagonal().cwiseSqrt().cwiseInverse();
  out.correlation = inverse_sd.asDiagonal() * *c * inverse_sd.asDiagonal();
  if (!held_on_bound.empty()) {
    out.std_error_note = "on its bound, where the data cannot move it:";
    for (std::size_t i : held_on_bound) out.std_error_note += " " + params[i].name;
    out.std_error_note += " (the others' are computed with it held there)";
  }
  for (std::size_t i = 0; i < params.size(); ++i) {
    if (!model.inert(i)) continue;
    out.std_error_note += (out.std_error_note.empty() ? "" : "; ") + params[i].name + " " + model.inert_reason(i);
  }
}

}  // namespace

FitOutcome fit(const Model& model, std::vector<double> start, Range range, int max_iterations, FitStop stop,
               unsigned jacobian_threads) {
  const std::vector<Parameter>& params = model.parameters();
  if (start.size() != params.size()) throw std::invalid_argument("diagnose fit: wrong number of starting values");
  const std::size_t axes = model.setup().axes.size();
  const std::size_t residual_count = range.count * axes;
  if (residual_count <= params.size()) throw std::invalid_argument("diagnose fit: fewer residuals than parameters");
  for (std::size_t i = 0; i < params.size(); ++i) start[i] = std::clamp(start[i], params[i].lower, params[i].upper);

  FitOutcome out;
  out.values = std::move(start);
  double* x = out.values.data();
  ceres::Problem problem;
  // Central differences, except where every evaluation runs the filter over the flight: forward ones there halve
  // the cost, and the filter's output is smooth in the parameters, so their first-order error stays far below the
  // step LM takes.
  ceres::CostFunction* cost = model.filter_runs()
                                  ? static_cast<ceres::CostFunction*>(new ForwardDifferenceCost(
                                        model, range, params.size(), residual_count, jacobian_threads))
                                  : central_difference_cost(model, range, params.size(), residual_count);
  problem.AddResidualBlock(new LastPointCache(cost), nullptr, x);
  std::vector<int> held;
  for (std::size_t i = 0; i < params.size(); ++i) {
    if (model.inert(i)) held.push_back(static_cast<int>(i));
  }
  // An inert parameter moves nothing: held at its start, it leaves the covariance of the others computable.
  if (!held.empty()) problem.SetManifold(x, new ceres::SubsetManifold(static_cast<int>(params.size()), held));
  for (std::size_t i = 0; i < params.size(); ++i) {
    if (model.inert(i)) continue;
    if (std::isfinite(params[i].lower)) problem.SetParameterLowerBound(x, static_cast<int>(i), params[i].lower);
    if (std::isfinite(params[i].upper)) problem.SetParameterUpperBound(x, static_cast<int>(i), params[i].upper);
  }

  ceres::Solver::Options options;
  options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  options.linear_solver_type = ceres::DENSE_QR;
  options.max_num_iterations = max_iterations;
  // Candidates are told apart by per-cent changes of the validation RMSE: a relative change of the cost below 1e-7
  // decides nothing, and the iterations that chase it were most of a diagnosis's time.
  options.function_tolerance = 1e-7;
  options.gradient_tolerance = 1e-10;
  options.parameter_tolerance = 1e-8;
  options.num_threads = 1;
  options.logging_type = ceres::SILENT;
  RecordCost record(out.convergence);
  options.callbacks.push_back(&record);
  ceres::Solver::Summary summary;
  if (stop == FitStop::parameter_precision) {
    // A comparison low-passed at f_c leaves 2 f_c / f_s of the samples independent.
    const ModelSetup& setup = model.setup();
    const double band = setup.lowpass_hz > 0.0 ? std::min(1.0, 2.0 * setup.lowpass_hz / model.signals().rate_hz) : 1.0;
    summary = estimator::solve_to_precision(problem, options, static_cast<double>(residual_count) * band);
  } else {
    ceres::Solve(options, &problem, &summary);
  }
  out.iterations = static_cast<int>(summary.iterations.size()) - 1;
  out.converged = summary.termination_type == ceres::CONVERGENCE;
  for (std::size_t i = 0; i < params.size(); ++i) {
    if (params[i].periodic) x[i] = std::remainder(x[i], 2.0 * std::numbers::pi);  // cost and Jacobian unchanged
  }

  standard_errors(problem, model, residual_count, out);
  return out;
}

}  // namespace imubridge::diagnose
