#include "diagnose/filter_identification.hpp"

#include <algorithm>
#include <chrono>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "diagnose/effects/library.hpp"
#include "diagnose/live_model.hpp"
#include "diagnose/model.hpp"
#include "diagnose/search.hpp"
#include "diagnose/signals.hpp"

namespace imubridge::diagnose {
namespace {

using estimator::FullBlock;

// identify's name for a parameter from its PARAMS.json path: below the group ("lever_arm.0", "drag_linear.1") for the
// 3-D model, the last part ("r", "mu") for a paper axis. Its summary prints these and its warnings name them.
std::string identify_name(const std::string& path) {
  if (path.starts_with("paper.")) return path.substr(path.rfind('.') + 1);
  const auto dot = path.find('.');
  return dot == std::string::npos ? path : path.substr(dot + 1);
}

// The fit of parameters `indices` as one of identify's groups.
estimator::FitReport report_of(const FitOutcome& fit, std::span<const std::size_t> indices,
                               const std::vector<std::string>& paths, std::string name) {
  estimator::FitReport r;
  r.name = std::move(name);
  const auto n = static_cast<Eigen::Index>(indices.size());
  estimator::Uncertainty& u = r.uncertainty;
  u.value.resize(n);
  u.std_error.resize(n);
  u.correlation.resize(n, n);
  for (Eigen::Index a = 0; a < n; ++a) {
    const std::size_t i = indices[static_cast<std::size_t>(a)];
    u.names.push_back(identify_name(paths[i]));
    u.value[a] = fit.values[i];
    u.std_error[a] = fit.std_errors[i];
    for (Eigen::Index b = 0; b < n; ++b) {
      if (fit.correlation.size() != 0)
        u.correlation(a, b) = fit.correlation(static_cast<Eigen::Index>(i),
                                              static_cast<Eigen::Index>(indices[static_cast<std::size_t>(b)]));
    }
  }
  if (fit.correlation.size() == 0) {
    u.failure = fit.covariance_failure.empty() ? "no covariance" : fit.covariance_failure;
    u.std_error.resize(0);
    u.correlation.resize(0, 0);
  }
  estimator::SolverReport lm;
  lm.iterations = fit.iterations;
  lm.converged = fit.converged;
  lm.initial_objective = fit.convergence.empty() ? 0.0 : fit.convergence.front();
  lm.final_objective = fit.convergence.empty() ? 0.0 : fit.convergence.back();
  lm.message = fit.converged ? "converged" : "stopped before converging";
  r.lm = lm;
  r.fit_objective = lm.final_objective;
  return r;
}

}  // namespace

estimator::IdentifyResult identify_by_filter_error(const estimator::ImuSeries& series,
                                                   const estimator::IdentifyOptions& options) {
  if (options.velocity != estimator::VelocitySource::filter)
    throw std::invalid_argument("identify_by_filter_error: the velocity source must be the filter");
  const bool full = options.model == estimator::ModelKind::full;
  if (options.hold.held(FullBlock::lever_arm) || options.hold.held(FullBlock::mounting))
    throw std::invalid_argument(
        "--hold lever_arm or mounting: from the IMU alone the base model's lever arm and mounting are always fitted");

  const Signals signals = prepare_signals(series, options.derivative_half_window);
  const estimator::Windows windows = estimator::resolve_windows(signals.t, options.train, options.validate);
  estimator::require_trainable(windows.train);
  const Range train = range_of(signals, windows.train), validation = range_of(signals, windows.validate);
  DiagnoseOptions diagnose_options;
  diagnose_options.train = windows.train;
  diagnose_options.validate = windows.validate;
  ModelSetup setup;
  setup.base = full ? ModelKind::full : ModelKind::paper;
  setup.signals = &signals;
  use_filter(setup, signals, diagnose_options);

  // identify's blocks beyond the base: the 3-D model's two drag laws and the horizontal bias (its z stays held).
  std::vector<const Effect*> effects;
  if (full) {
    if (!options.hold.held(FullBlock::drag_linear)) effects.push_back(find_effect("linear_drag"));
    if (!options.hold.held(FullBlock::drag_quadratic)) effects.push_back(find_effect("quadratic_drag"));
    if (!options.hold.held(FullBlock::accel_bias)) effects.push_back(find_effect("accel_bias"));
  }
  const Model model(signals, setup, effects);

  const auto started = std::chrono::steady_clock::now();
  std::vector<double> start = model.base_start(train);
  std::vector<std::size_t> drag;
  for (std::size_t e = 0; e < effects.size(); ++e) {
    for (std::size_t i = model.effect_offset(e); i < model.effect_offset(e) + model.effect_size(e); ++i) {
      start.push_back(model.parameters()[i].initial);
      if (effects[e]->adds_drag()) drag.push_back(i);
    }
  }
  if (!drag.empty()) model.scan_drag_start(start, drag, train, cores());
  const FitOutcome fit = diagnose::fit(model, start, train, 50, FitStop::parameter_precision, cores());
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();

  estimator::IdentifyResult result;
  result.params = live_params(model, fit.values, fit.std_errors);
  record_fit(result.params, model, fit.values, train, validation);
  result.params.identification.method = "filter-error";
  result.params.effects.clear();  // identify's blocks, not effects a diagnosis added

  // identify names each parameter by its PARAMS.json path; the filter's process noise, which has none, by its own.
  std::vector<std::string> paths = parameter_paths(model);
  for (std::size_t i = 0; i < paths.size(); ++i) {
    if (paths[i].empty()) paths[i] = "full." + model.parameters()[i].name;
  }
  if (full) {
    std::vector<std::size_t> all(paths.size());
    for (std::size_t i = 0; i < all.size(); ++i) all[i] = i;
    result.fits.push_back(report_of(fit, all, paths, "full"));
  } else {
    for (std::size_t a = 0; a < setup.axes.size(); ++a) {
      const std::vector<std::size_t> axis{4 * a, 4 * a + 1, 4 * a + 2, 4 * a + 3};
      result.fits.push_back(report_of(fit, axis, paths, setup.axes[a] == 0 ? "paper.x" : "paper.y"));
    }
  }
  for (estimator::FitReport& r : result.fits) {
    r.fit_samples = train.count;
    r.validation_samples = validation.count;
    r.solve_seconds = seconds;
  }
  return result;
}

}  // namespace imubridge::diagnose
