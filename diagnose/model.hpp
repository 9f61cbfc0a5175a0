#pragma once
// The model `imubridge diagnose` fits: a base model (the paper's eq. 14 per axis, or the 3-D rigid body and
// mounting of docs/model.md) plus a list of effects (effects/effect.hpp), evaluated in the effects' stages, and its
// generic fit: Levenberg-Marquardt (Ceres) on every free parameter with a numeric-difference Jacobian (central;
// forward when every evaluation runs the drag-velocity filter), because effects such as a gyro bias or the
// self-consistent velocity change the velocity integrated over the whole flight. Deterministic; one fit runs on one
// thread, and a Model serves one thread at a time (the search gives each thread models of its own).
#include <Eigen/Core>
#include <cstddef>
#include <list>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "diagnose/effects/effect.hpp"
#include "diagnose/signals.hpp"
#include "estimator/on_threads.hpp"
#include "estimator/params.hpp"

namespace imubridge::diagnose {

// A run of samples, [first, first + count).
struct Range {
  std::size_t first = 0, count = 0;
};

// The samples of `signals` inside the window.
Range range_of(const Signals& signals, const estimator::TimeWindow& window);

// Measured and predicted specific force in the residual's frame (paper: sensor axes; full: levelled body axes),
// per diagnosed axis; the residual is measured - predicted.
struct Evaluation {
  AxisValues measured, predicted;
  AxisValues residual() const;
};

class Model {
 public:
  // Throws std::invalid_argument for no diagnosed axis, a reference velocity the signals do not have, or an effect
  // that does not apply (Effect::why_not).
  Model(const Signals& signals, ModelSetup setup, std::vector<const Effect*> effects = {});

  const ModelSetup& setup() const { return setup_; }
  const Signals& signals() const { return *setup_.signals; }
  const std::vector<const Effect*>& effects() const { return effects_; }
  // Every parameter: the base model's first, then each effect's in order.
  const std::vector<Parameter>& parameters() const { return parameters_; }
  std::size_t base_size() const { return base_size_; }
  // True when the velocity comes from the filter and the model has a drag for it to fuse (else it has nothing to
  // measure and no prediction reads a velocity): every evaluation then runs it.
  bool filter_runs() const;
  // True for a parameter held at its start: one nothing depends on (the filter's process noise while the filter has no
  // drag to run with), or one whose bounds meet.
  bool inert(std::size_t i) const;
  // Why parameter i is inert, as its missing standard error says it ("" when it is not).
  std::string inert_reason(std::size_t i) const;
  // velocity `filter`: the filter's process noise at p (m/s^2/sqrt(Hz)), the base's last parameter; else the setup's.
  double process_noise(std::span<const double> p) const;
  static constexpr std::string_view kProcessNoiseParameter = "process_noise_log10";
  // Where effect i's parameters start in the full vector, and how many it has.
  std::size_t effect_offset(std::size_t i) const { return offsets_[i]; }
  std::size_t effect_size(std::size_t i) const { return offsets_[i + 1] - offsets_[i]; }

  // Stages 1-3 (effect.hpp) over the whole series: the velocity is integrated from the first sample.
  ModelInputs inputs(std::span<const double> p) const;
  Evaluation evaluate(std::span<const double> p, Range range) const;
  // Residuals sample-major (sample k, axis i at k * axes + i): what the fit minimises.
  void residuals(std::span<const double> p, Range range, double* out) const;
  // sqrt(mean residual^2) over the range and the diagnosed axes.
  double rmse(std::span<const double> p, Range range) const;

  // The base model's starting values on `range`: the paper's closed-form linear fit of eq. (14) per axis
  // (estimator::paper_linear_fit); for the full model no lever arm and the mounting that levels the mean specific
  // force (Signals::level_mounting).
  std::vector<double> base_start(Range range) const;

  // From the IMU alone (velocity `filter`) the drag sets the filter velocity's time constant, and a fit started far
  // from the right one settles in a basin of its own: sets parameters `indices` of `p` (all drag coefficients) to the
  // one of kDragStarts with the lowest RMSE on `range`, the others held. One filter run per value, shared among
  // `threads` threads (the same choice on any number).
  void scan_drag_start(std::vector<double>& p, std::span<const std::size_t> indices, Range range,
                       unsigned threads = 1) const;
  // Decades spanning multirotors' drag, linear (1/s) and quadratic (1/m) alike.
  static constexpr double kDragStarts[] = {0.01, 0.03, 0.1, 0.3, 1.0, 3.0};

 private:
  // Stages 1-3 for samples [0, until) (velocity `filter` runs its filter only that far; the other sources fill
  // everything), into `in`, whose vectors are reused. `plain_gyro`: whether in.gyro and in.gyro_rate hold the
  // signals' own (then they are not copied again when nothing changes them); updated.
  void compute_inputs(std::span<const double> p, std::size_t until, ModelInputs& in, bool& plain_gyro) const;
  // Stages 1 and 2 into in.gyro and in.gyro_rate (compute_inputs' plain_gyro); returns the time offset tau.
  double gyro_inputs(std::span<const double> p, ModelInputs& in, bool& plain_gyro) const;
  // velocity `filter`: the drag-velocity filter run with the model at p from the series' first sample to `until`, on
  // block means; its one-step-ahead air velocity per sample (so that the residual is the filter's innovation), into
  // `velocity` (resized to the series).
  void filter_velocity(std::span<const double> p, std::size_t until, std::vector<Eigen::Vector3d>& velocity) const;
  // The measured specific force of samples [0, count) (IMU axes) without the lever arm's reading, at the full rate:
  // from the rotation rate `gyro` (time-shifted as the filter sees it) and the signals' smoothed derivative.
  std::vector<Eigen::Vector3d> accel_without_lever_arm(const estimator::FullModelParams& params,
                                                       std::span<const Eigen::Vector3d> gyro, std::size_t count) const;
  // The inputs for p, recomputed only when a parameter they depend on changed: most of a numeric Jacobian's
  // evaluations perturb parameters that act after stage 3. Not thread-safe (the fit is single-threaded).
  const ModelInputs& inputs_for(std::span<const double> p, std::size_t until) const;
  // evaluate() into `e`, whose vectors are reused (residuals() keeps one: a fit evaluates thousands of times).
  void evaluate_into(std::span<const double> p, Range range, Evaluation& e) const;
  // The base model's predicted reading (IMU axes) on `range` into `predicted` (zeros on entry); sets ctx's paper
  // parameters or imu_to_body.
  void predict_base(std::span<const double> p, Range range, const DragLaw& effect_drag, PredictionContext& ctx,
                    std::vector<Eigen::Vector3d>& predicted) const;

  ModelSetup setup_;
  std::vector<const Effect*> effects_;
  std::vector<Parameter> parameters_;
  std::size_t base_size_ = 0;
  std::vector<std::size_t> offsets_;         // effects' first parameters, then the total
  std::optional<ModelInputs> fixed_inputs_;  // when no parameter changes stages 1-3
  std::vector<bool> input_parameter_;        // which parameters stages 1-3 depend on
  mutable std::vector<double> cached_key_;   // their values for cached_inputs_
  mutable std::optional<ModelInputs> cached_inputs_;
  mutable std::size_t cached_until_ = 0;    // cached_inputs_ hold samples [0, cached_until_)
  mutable bool cached_plain_gyro_ = false;  // compute_inputs' plain_gyro for cached_inputs_
  // The measured specific force low-passed (IMU axes), per range evaluated: it does not depend on the parameters.
  // Not thread-safe either.
  std::span<const Eigen::Vector3d> lowpassed_measurement(Range range) const;
  mutable std::list<std::pair<Range, std::vector<Eigen::Vector3d>>> lowpassed_;  // a list: spans into it stay valid
  // velocity `filter`: the filter's input, block means of the samples without a time offset (filter_velocity). Not
  // thread-safe either.
  mutable std::vector<estimator::ImuSample> block_means_;
  mutable std::vector<double> block_means_key_;  // the lever arm's values block_means_ were made for; empty: none
  // evaluate_into's and residuals()' working space, reused from one evaluation to the next. Not thread-safe either.
  mutable std::vector<Eigen::Vector3d> predicted_scratch_;
  mutable Evaluation residual_scratch_;
};

struct FitOutcome {
  std::vector<double> values;
  std::vector<double> std_errors;  // NaN when the covariance could not be computed
  Eigen::MatrixXd correlation;     // of the estimates; empty when the covariance could not be computed
  std::string covariance_failure;  // why not, or empty
  // Why some standard errors are NaN though the covariance was computed (parameters held on a bound), or empty.
  std::string std_error_note;
  std::vector<double> convergence;  // sqrt(sum of squared residuals) at the start and after each iteration
  int iterations = 0;
  bool converged = false;
};

// How far LM goes: until a relative cost change of 1e-7, as diagnose needs to compare candidates by the costs they
// reach (the F-test), or until the parameters are within a third of a standard error of the optimum
// (identification/precise_solve.hpp), which is all a fit that reports parameters can tell (identify).
enum class FitStop { cost, parameter_precision };

// The cores fits may spread over (never 0).
using estimator::cores;

// LM from `start` (clamped into the parameters' bounds) on the range's residuals. Standard errors from
// ceres::Covariance (dense SVD) scaled by the residual variance, as identification/least_squares.cpp does. When the
// model runs the filter, its Jacobian's columns are shared among `jacobian_threads` threads; the result does not depend
// on how many.
FitOutcome fit(const Model& model, std::vector<double> start, Range range, int max_iterations = 50,
               FitStop stop = FitStop::cost, unsigned jacobian_threads = 1);

}  // namespace imubridge::diagnose
