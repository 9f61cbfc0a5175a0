#pragma once
// The model `imubridge diagnose` fits: a base model (the paper's eq. 14 per axis, or the 3-D rigid body and
// mounting of docs/model.md) plus a list of effects (effects/effect.hpp), evaluated in the effects' stages, and its
// generic fit: Levenberg-Marquardt (Ceres) on every free parameter with a central numeric-difference Jacobian,
// because effects such as a gyro bias or the self-consistent velocity change the velocity integrated over the whole
// flight. Deterministic and single-threaded.
#include <cstddef>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "diagnose/effects/effect.hpp"
#include "diagnose/signals.hpp"

namespace imubridge::diagnose {

// A run of samples, [first, first + count).
struct Range {
  std::size_t first = 0, count = 0;
};

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

 private:
  ModelInputs compute_inputs(std::span<const double> p) const;
  // The inputs for p, recomputed only when a parameter they depend on changed: most of a numeric Jacobian's
  // evaluations perturb parameters that act after stage 3. Not thread-safe (the fit is single-threaded).
  const ModelInputs& inputs_for(std::span<const double> p) const;

  ModelSetup setup_;
  std::vector<const Effect*> effects_;
  std::vector<Parameter> parameters_;
  std::size_t base_size_ = 0;
  std::vector<std::size_t> offsets_;  // effects' first parameters, then the total
  std::optional<ModelInputs> fixed_inputs_;  // when no parameter changes stages 1-3
  std::vector<bool> input_parameter_;        // which parameters stages 1-3 depend on
  mutable std::vector<double> cached_key_;   // their values for cached_inputs_
  mutable std::optional<ModelInputs> cached_inputs_;
};

struct FitOutcome {
  std::vector<double> values;
  std::vector<double> std_errors;  // NaN when the covariance could not be computed
  std::string covariance_failure;  // why not, or empty
  std::vector<double> convergence;  // sqrt(sum of squared residuals) at the start and after each iteration
  int iterations = 0;
  bool converged = false;
};

// LM from `start` (clamped into the parameters' bounds) on the range's residuals. Standard errors from
// ceres::Covariance (dense SVD) scaled by the residual variance, as estimator/least_squares.cpp does.
FitOutcome fit(const Model& model, std::vector<double> start, Range range);

}  // namespace imubridge::diagnose
