#pragma once
// One named, documented extension of the accelerometer model (docs/effects.md): its parameters, whether it can be
// tried on these data, and what it does to the model. The model (diagnose/model.hpp) evaluates in fixed stages; an
// effect declares the stages it acts in (Effect::stages) and overrides their hooks, and the model calls its hooks
// for those stages only:
//   1. gyro        adjust_gyro          the gyro the model uses (gyro bias)
//   2. timing      time_offset          the model's inputs are taken at t - tau (accel-gyro time offset)
//   3. velocity    wind_ned, drag_in_dynamics, add_drag
//                                       air velocity and the drag law; drag in the vehicle's own dynamics
//   4. sensor      adjust_sensor        the predicted reading in IMU axes, through the sensor's errors (scale, cross)
//   5. prediction  add_prediction       terms added to the prediction in the residual's frame (bias, vibration,
//                                       lever arm z)
//   and measured_thrust: the base model takes T from the body-z reading instead of g.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <functional>
#include <limits>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "diagnose/signals.hpp"
#include "estimator/drag_velocity.hpp"
#include "estimator/paper_model.hpp"
#include "identification/identify_choices.hpp"

namespace imubridge::diagnose {

// The base model and the velocity the drag term sees are identify's choices (identification/identify_choices.hpp):
// with the filter, its one-step prediction (the filter error method, docs/identification.md).
using estimator::ModelKind;
using estimator::VelocitySource;

// What the effects know of the diagnosis.
struct ModelSetup {
  ModelKind base = ModelKind::paper;
  VelocitySource velocity = VelocitySource::reference;
  std::vector<int> axes{0, 1};  // diagnosed axes: 0 = x, 1 = y (paper: sensor axes; full: levelled body axes)
  const Signals* signals = nullptr;
  std::vector<std::pair<double, double>> ignore_bands;  // Hz: the frequency search leaves these alone
  // > 0: measured and predicted are low-passed alike (zero phase, lowpass.hpp) before they are compared, Hz.
  double lowpass_hz = 0.0;
  // velocity `filter`: the filter's noises (the measurement noise set from the data: docs/identification.md).
  estimator::DragVelocityConfig filter{};
  std::size_t filter_block = 1;  // samples per block mean the filter runs on (identification_block)
  // The base model's lever arm is searched within +-this per component, m (the paper's r within [0, this]);
  // infinite unless a fit ran beyond the plausibility table (diagnose then refits the base inside it).
  double lever_arm_bound = std::numeric_limits<double>::infinity();
  // The paper model's mu is searched within [0, this], 1/m; infinite unless its fit ran beyond the plausibility table.
  double drag_bound = std::numeric_limits<double>::infinity();
  // With the reference as the velocity: the gyro's bias measured against the reference's attitude on the training
  // window (gyro_against_reference), rad/s, the signals' axes. gyro_bias then takes it instead of fitting one the
  // specific force hardly shows.
  std::optional<Eigen::Vector3d> reference_gyro_bias;
  // Effect parameters held at zero, their absence, by held_name: one axis of an effect whose fit went past the
  // plausibility table on it while its other axes stayed inside (diagnose/search.cpp, axes_to_hold).
  std::vector<std::string> held_at_zero{};
};

// How ModelSetup::held_at_zero names an effect's parameter: "linear_drag.k.y".
inline std::string held_name(std::string_view effect, std::string_view parameter) {
  return std::string(effect) + "." + std::string(parameter);
}
// Whether `held` (ModelSetup::held_at_zero's names) holds that effect's parameter.
inline bool holds(const std::vector<std::string>& held, std::string_view effect, std::string_view parameter) {
  return std::find(held.begin(), held.end(), held_name(effect, parameter)) != held.end();
}

// The stages an effect acts in. One declaration: the model calls only these stages' hooks, and reads from it which
// effects change its inputs (stages 1-3) and which add to the drag law, so no separate flag can disagree with them.
struct Stages {
  bool gyro = false;              // 1: adjust_gyro
  bool timing = false;            // 2: time_offset
  bool wind = false;              // 3: wind_ned
  bool drag = false;              // 3: add_drag
  bool drag_in_dynamics = false;  // 3: the drag law acts in the vehicle's dynamics, which give the velocity
  bool measured_thrust = false;   // T from the body-z reading instead of g
  bool sensor = false;            // 4: adjust_sensor
  bool prediction = false;        // 5: add_prediction
};

struct Parameter {
  std::string name;  // unique within its effect ("k.x", "tau", ...)
  std::string unit;
  double initial = 0.0;
  double lower = -std::numeric_limits<double>::infinity();
  double upper = std::numeric_limits<double>::infinity();
  // An angle the model reads only through its sine and cosine: the fit reports it in (-pi, pi], where any 2 pi
  // it wandered by means nothing.
  bool periodic = false;
};

// Horizontal drag per body axis as a specific force, -k v - mu |v| v (estimator/drag_law.hpp), on the air velocity.
struct DragLaw {
  Eigen::Vector2d k = Eigen::Vector2d::Zero();   // 1/s
  Eigen::Vector2d mu = Eigen::Vector2d::Zero();  // 1/m
};

// The model's inputs at every sample once stages 1-3 have run.
struct ModelInputs {
  std::vector<Eigen::Vector3d> gyro, gyro_rate;  // IMU axes
  std::vector<Eigen::Vector3d> velocity;         // body-axis AIR velocity (ground velocity minus wind), m/s
  // body -> NED (reference, or integrated from the gyro); empty with velocity `filter`, whose attitude is its own state
  std::vector<Eigen::Quaterniond> attitude;
  std::vector<double> thrust;  // T, m/s^2: g, or the measured body-z reading (measured_thrust)
};

// What stage 5 sees: the inputs and the base model's current geometry, over samples [first, first + count).
struct PredictionContext {
  const ModelSetup& setup;
  const ModelInputs& inputs;
  std::vector<estimator::PaperAxisParams> paper;              // paper base: per diagnosed axis
  Eigen::Matrix3d imu_to_body = Eigen::Matrix3d::Identity();  // full base: R_bs
  std::size_t first = 0, count = 0;
};

// Per diagnosed axis (in ModelSetup::axes order), one value per sample of the range.
using AxisValues = std::vector<std::vector<double>>;

// For effects whose starting values come from the data: the current model's training residual.
struct StartContext {
  const ModelSetup& setup;
  std::span<const double> t;   // training window's times
  const AxisValues& residual;  // training residual per diagnosed axis
};

// What an effect's live form sees (Effect::to_live).
struct LiveContext {
  const ModelSetup& setup;
  // The full base's R_bs (a bias found in the residual's frame, the body's, is R_bs^T b in IMU axes); else identity.
  Eigen::Matrix3d imu_to_body = Eigen::Matrix3d::Identity();
  // The model's body -> NED attitude at the first sample, when it has one (with the reference or eq. 12's velocity).
  std::function<std::optional<Eigen::Quaterniond>()> first_attitude;
};

class Effect {
 public:
  virtual ~Effect() = default;
  virtual std::string_view name() const = 0;
  // Why this effect cannot be tried with this base model, velocity source or effect set, or nullopt.
  virtual std::optional<std::string> why_not(const ModelSetup&, std::span<const std::string> in_model) const {
    (void)in_model;
    return std::nullopt;
  }
  // Effects this one only shows together with, from the library, when the model lacks them: the search fits the
  // candidate with them added first (docs/effects.md, "Compound effects"). Empty by default.
  virtual std::vector<std::string> needs(const ModelSetup&, std::span<const std::string> in_model) const {
    (void)in_model;
    return {};
  }
  virtual std::vector<Parameter> parameters(const ModelSetup&) const = 0;
  // Starting values (defaults: each Parameter::initial, already in `p`); an error when the data offer none.
  virtual std::optional<std::string> start(const StartContext&, std::span<double> p) const {
    (void)p;
    return std::nullopt;
  }
  // Further starting points the fit tries besides start()'s, for effects whose fit has more than one basin; the
  // search keeps the fit with the lowest training cost.
  virtual std::vector<std::vector<double>> more_starts(std::span<const double> start) const {
    (void)start;
    return {};
  }
  virtual Stages stages() const = 0;
  // Stages 1-3 depend on this effect's parameters: the model then recomputes its inputs at every evaluation.
  bool changes_inputs() const {
    const Stages s = stages();
    return s.gyro || s.timing || s.wind || s.drag_in_dynamics;
  }
  bool adds_drag() const { return stages().drag; }

  virtual void adjust_gyro(std::span<const double>, const ModelSetup&, std::vector<Eigen::Vector3d>&) const {}
  virtual double time_offset(std::span<const double>) const { return 0.0; }
  virtual Eigen::Vector3d wind_ned(std::span<const double>) const { return Eigen::Vector3d::Zero(); }
  virtual void add_drag(std::span<const double>, const ModelSetup&, DragLaw&) const {}
  // `predicted` and `measured` hold the range's samples in IMU axes (the paper model fills only its axes).
  virtual void adjust_sensor(std::span<const double>, const ModelSetup&, std::span<Eigen::Vector3d> predicted,
                             std::span<const Eigen::Vector3d> measured) const {
    (void)predicted, (void)measured;
  }
  virtual void add_prediction(std::span<const double>, const PredictionContext&, AxisValues&) const {}

  // Its live form (docs/effects.md, "Live"), next to its fit: where PARAMS.json keeps each parameter (the path its
  // standard error is recorded under, "full.drag_linear.0"), and what the fitted values add to the live estimator's
  // parameters. An effect the estimator does not run keeps both defaults: its parameters under
  // "effects.NAME.PARAMETER", and nothing added.
  virtual std::string live_path(const Parameter& p) const { return "effects." + std::string(name()) + "." + p.name; }
  // Why the live estimator cannot run this effect at all, or nullopt (PARAMS.json's not_live: the file is refused).
  virtual std::optional<std::string_view> live_refusal() const { return std::nullopt; }
  virtual void to_live(std::span<const double> values, std::span<const Parameter> parameters, const LiveContext&,
                       estimator::FullModelParams& live) const {
    (void)values, (void)parameters, (void)live;
  }
};

// "x", "y" or "z".
inline std::string axis_name(int axis) { return std::string(1, static_cast<char>('x' + axis)); }
// The axis a per-axis parameter's name ends with: "k.x" -> 0, "bias.z" -> 2.
inline int axis_of(const Parameter& p) {
  const char last = p.name.empty() ? '?' : p.name.back();
  if (last < 'x' || last > 'z') throw std::logic_error("diagnose: parameter " + p.name + " names no axis");
  return last - 'x';
}
// The live form of an effect with one parameter per axis (Effect::live_path, Effect::to_live): kept in PARAMS.json
// at "full.BLOCK.AXIS", its values added to the estimator's `field` at their axes.
inline std::string per_axis_live_path(std::string_view block, const Parameter& p) {
  return "full." + std::string(block) + "." + std::to_string(axis_of(p));
}
template <typename Field>
void add_per_axis(std::span<const double> values, std::span<const Parameter> parameters, Field& field) {
  for (std::size_t i = 0; i < parameters.size(); ++i) field[axis_of(parameters[i])] += values[i];
}

// One parameter per diagnosed axis: "<prefix>.x", "<prefix>.y".
inline std::vector<Parameter> per_axis(const ModelSetup& setup, const std::string& prefix, const std::string& unit,
                                       double lower, double upper) {
  std::vector<Parameter> out;
  for (int axis : setup.axes) out.push_back({prefix + "." + axis_name(axis), unit, 0.0, lower, upper});
  return out;
}

inline bool contains(std::span<const std::string> names, std::string_view name) {
  for (const std::string& n : names) {
    if (n == name) return true;
  }
  return false;
}

}  // namespace imubridge::diagnose
