#include "diagnose/search.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <atomic>
#include <boost/math/distributions/fisher_f.hpp>
#include <boost/math/distributions/students_t.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <future>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <tuple>

#include "diagnose/effects/library.hpp"
#include "diagnose/gyro_against_reference.hpp"
#include "diagnose/live_model.hpp"
#include "diagnose/lowpass.hpp"
#include "diagnose/model.hpp"
#include "diagnose/residual_analysis.hpp"
#include "diagnose/signals.hpp"
#include "identification/identify.hpp"
#include "identification/plausibility.hpp"
#include "identification/velocity_scores.hpp"

namespace imubridge::diagnose {
namespace {

// Residuals that follow a manoeuvre stay correlated for about as long as it lasts, around a second: the effective
// sample count looks that far.
constexpr double kCorrelationSpanS = 1.0;

double sum_of_squares(const AxisValues& residual) {
  double sum = 0.0;
  for (const std::vector<double>& axis : residual) {
    for (double r : axis) sum += r * r;
  }
  return sum;
}

// A multirotor in flight never tilts past 90 degrees: its thrust would point down. From the IMU alone the attitude is
// integrated from the gyro, and an effect that changes it (a gyro bias, say) can buy a better fit by bending the
// velocity integrated from that attitude into a shape no flight has: the fitted attitude then turns past 90 degrees.
constexpr double kMaxFlightTiltRad = std::numbers::pi / 2;

// The largest tilt (angle between body z and down) of the model's attitude over the training and validation windows.
double largest_tilt(const Model& model, std::span<const double> p, Range train, Range validation) {
  const ModelInputs inputs = model.inputs(p);
  double largest = 0.0;
  for (const Range r : {train, validation}) {
    for (std::size_t k = r.first; k < r.first + r.count; ++k) {
      const double down = (inputs.attitude[k] * Eigen::Vector3d::UnitZ()).z();  // NED: 1 when level
      largest = std::max(largest, std::acos(std::clamp(down, -1.0, 1.0)));
    }
  }
  return largest;
}

// Why a fitted candidate describes no flight, or nullopt.
std::optional<std::string> unflyable(const Model& model, std::span<const double> p, Range train, Range validation) {
  const double tilt = largest_tilt(model, p, train, validation);
  if (tilt <= kMaxFlightTiltRad) return std::nullopt;
  char why[160];
  std::snprintf(why, sizeof why,
                "implausible: its fit tilts the gyro-integrated attitude to %.0f deg, past the 90 deg no multirotor in "
                "flight reaches",
                tilt * 180.0 / std::numbers::pi);
  return why;
}

// Why the parameters [first, end) of a fit are not determined by the data, or nullopt: a standard error that cannot
// be computed, or a joint Wald statistic θᵀ Σ⁻¹ θ over them no larger than their number, which is what noise alone
// gives an effect that is not there (for one parameter: a standard error as large as the value). Jointly, because an
// effect's own parameters may be told apart only together: an accelerometer scale's common part hides in the lever
// arm (docs/effects.md) while the ratio of its two axes is sharp.
std::optional<std::string> undetermined(const Model& model, const FitOutcome& fit, std::size_t first) {
  // An effect with no parameters of its own (the measured thrust in place of g, a self-consistent velocity) has
  // nothing the data must determine: the other rules judge it.
  // A parameter held at its only value (an axis held at zero) is not the data's to determine.
  std::vector<std::size_t> free;
  for (std::size_t k = first; k < fit.values.size(); ++k) {
    if (!model.inert(k)) free.push_back(k);
  }
  if (free.empty()) return std::nullopt;
  const auto n = static_cast<Eigen::Index>(free.size());
  Eigen::VectorXd value(n), se(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const std::size_t k = free[static_cast<std::size_t>(i)];
    se[i] = fit.std_errors.empty() ? std::numeric_limits<double>::quiet_NaN() : fit.std_errors[k];
    if (!std::isfinite(se[i])) {
      return "undetermined: the standard error of " + model.parameters()[k].name + " cannot be computed (" +
             (fit.covariance_failure.empty() ? std::string("the covariance is singular") : fit.covariance_failure) +
             ")";
    }
    value[i] = fit.values[k];
  }
  // The covariance block from the correlations, or from the standard errors alone when there are none.
  Eigen::MatrixXd correlation = Eigen::MatrixXd::Identity(n, n);
  if (fit.correlation.rows() == static_cast<Eigen::Index>(fit.values.size())) {
    for (Eigen::Index i = 0; i < n; ++i) {
      for (Eigen::Index j = 0; j < n; ++j)
        correlation(i, j) = fit.correlation(static_cast<Eigen::Index>(free[static_cast<std::size_t>(i)]),
                                            static_cast<Eigen::Index>(free[static_cast<std::size_t>(j)]));
    }
  }
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(se.asDiagonal() * correlation * se.asDiagonal());
  // A singular block (a pivot of zero or less) determines nothing.
  const double wald =
      ldlt.info() == Eigen::Success && (ldlt.vectorD().array() > 0.0).all() ? value.dot(ldlt.solve(value)) : 0.0;
  if (wald > static_cast<double>(n)) return std::nullopt;
  char why[240];
  std::snprintf(why, sizeof why,
                "undetermined: its parameters' Wald statistic %.3g is no larger than their number (%td), what noise "
                "alone gives (standard errors norm %.3g, values norm %.3g): the data cannot tell it from none",
                wald, n, se.norm(), value.norm());
  return why;
}

// What users fly with, larger the better: the validation velocity's RMSE negated (with the reference), else the
// filter's validation log-likelihood; nullopt when the model gives none.
std::optional<double> flight_score(const std::optional<double>& velocity, const std::optional<double>& likelihood,
                                   bool judged_by_velocity) {
  if (judged_by_velocity) return velocity ? std::optional(-*velocity) : std::nullopt;
  return likelihood;
}

// Whether a model scoring `score` flies no worse than one scoring `reference`: within flight_tolerance of its size,
// which one validation window cannot tell apart (DiagnoseOptions::flight_tolerance).
bool flies_no_worse(double score, double reference, const DiagnoseOptions& options) {
  return score >= reference - options.flight_tolerance * std::abs(reference);
}

// Which candidates the step may take when judged by the flight: those passing every rule that fly no worse than the
// best of them. Without the flight's rules, every candidate that passes.
std::vector<bool> flying_best(const std::vector<CandidateTrial>& trials, bool judged_by_velocity,
                              const DiagnoseOptions& options) {
  const auto score = [&](const CandidateTrial& t) {
    return flight_score(t.velocity_validation, t.likelihood_validation, judged_by_velocity);
  };
  std::optional<double> best;
  for (const CandidateTrial& t : trials) {
    if (t.significant && score(t) && (!best || *score(t) > *best)) best = score(t);
  }
  std::vector<bool> out(trials.size());
  for (std::size_t i = 0; i < trials.size(); ++i) {
    const std::optional<double> f = score(trials[i]);
    out[i] = trials[i].significant && (!options.choose_by_flight || !best || !f || flies_no_worse(*f, *best, options));
  }
  return out;
}

// The current model: its effects, fitted values and what they give.
struct State {
  std::vector<const Effect*> effects;
  FitOutcome fit;
  ModelFit summary;
  AxisValues train_residual, validation_residual;
  std::vector<std::string> implausible_limits;  // the plausibility limits this model already exceeds
  std::vector<std::string> held_at_zero;        // its effects' axes held at zero (ModelSetup::held_at_zero's names)
  estimator::ModelParams params;                // the model as the live estimator runs it
};

std::vector<std::string> names_of(const std::vector<const Effect*>& effects) {
  std::vector<std::string> names;
  for (const Effect* e : effects) names.emplace_back(e->name());
  return names;
}

ParameterEstimate estimate(const Parameter& p, const FitOutcome& fit, std::size_t i) {
  return {p.name, fit.values[i], fit.std_errors[i], p.unit};
}

// The base, or the effect a parameter of `model` belongs to, by name.
std::string owner_of(const Model& model, std::size_t i) {
  for (std::size_t e = 0; e < model.effects().size() && i >= model.base_size(); ++e) {
    if (i < model.effect_offset(e + 1)) return std::string(model.effects()[e]->name());
  }
  return "base";
}

std::vector<std::string> at_bounds(const Model& model, std::span<const double> values) {
  std::vector<std::string> owners;
  for (std::size_t i = 0; i < model.parameters().size(); ++i) owners.push_back(owner_of(model, i));
  return parameters_at_bounds(model.parameters(), values, owners);
}

// The effects' parameters held at zero (ModelSetup::held_at_zero): none of them is free.
std::size_t held_effect_parameters(const Model& model) {
  std::size_t held = 0;
  for (std::size_t i = model.base_size(); i < model.parameters().size(); ++i) held += model.inert(i);
  return held;
}

ModelFit describe(const Model& model, const FitOutcome& fit, Range train, Range validation) {
  ModelFit out;
  out.at_bounds = at_bounds(model, fit.values);
  out.effects = names_of(model.effects());
  const std::vector<Parameter>& params = model.parameters();
  for (std::size_t i = 0; i < model.base_size(); ++i) out.base_params.push_back(estimate(params[i], fit, i));
  for (std::size_t e = 0; e < model.effects().size(); ++e) {
    std::vector<ParameterEstimate> list;
    for (std::size_t i = model.effect_offset(e); i < model.effect_offset(e) + model.effect_size(e); ++i)
      list.push_back(estimate(params[i], fit, i));
    out.effect_params.push_back(std::move(list));
  }
  out.free_parameters = params.size() - held_effect_parameters(model);
  out.rmse_train = model.rmse(fit.values, train);
  out.rmse_validation = model.rmse(fit.values, validation);
  out.convergence = fit.convergence;
  out.std_error_failure = fit.covariance_failure.empty() ? fit.std_error_note : fit.covariance_failure;
  return out;
}

State settle(const Model& model, FitOutcome fit, Range train, Range validation) {
  State s;
  s.effects = model.effects();
  s.summary = describe(model, fit, train, validation);
  s.train_residual = model.evaluate(fit.values, train).residual();
  s.validation_residual = model.evaluate(fit.values, validation).residual();
  s.fit = std::move(fit);
  return s;
}

std::vector<ResidualAnalysis> analyse(const Model& model, const State& state, Range validation,
                                      const DiagnoseOptions& options) {
  const Signals& s = model.signals();
  const ModelInputs inputs = model.inputs(state.fit.values);
  const std::vector<NamedSignal> candidates = candidate_signals(s, inputs.velocity, validation.first, validation.count);
  const std::span<const double> t(s.t.data() + validation.first, validation.count);
  AnalysisOptions analysis;
  analysis.ignore_bands = options.ignore_bands;
  analysis.significance = options.significance;
  // The angular acceleration is a fit over +-kDerivativeHalfWindowS: its noise correlates the residual across the
  // whole window even for a perfect model, so whiteness is judged at lags beyond it.
  // A band limit correlates it over about one period of its cutoff.
  analysis.whiteness_lag_spacing_s =
      std::max(2.0 * kDerivativeHalfWindowS, options.lowpass_hz > 0.0 ? 1.0 / options.lowpass_hz : 0.0);
  std::vector<ResidualAnalysis> out;
  for (const std::vector<double>& r : state.validation_residual)
    out.push_back(analyse_residual(t, r, candidates, analysis));
  return out;
}

std::string describe_rule(const DiagnoseOptions& o, bool judged_by_velocity) {
  char text[300];
  std::snprintf(text, sizeof text,
                "F-test on the validation residual sums of squares (effective sample count from the residual's "
                "autocorrelation over %.1f s), p < %g / candidates tried, and validation RMSE lower by at least %g %%",
                kCorrelationSpanS, o.significance, 100.0 * o.min_improvement);
  std::string rule = text;
  if (o.lowpass_hz > 0.0) {
    std::snprintf(text, sizeof text, "; model and measurement compared below %g Hz (zero-phase Butterworth)",
                  o.lowpass_hz);
    rule += text;
  }
  if (judged_by_velocity && o.flight_rules)
    rule +=
        "; a first drag also passes by the velocity's test (its validation velocity's gain over zero velocity's, "
        "a one-sided t-test on 1-s blocks at the same level)";
  if (judged_by_velocity)
    rule +=
        "; gyro_bias is measured against the reference's attitude and passes by that attitude's test (its bias on "
        "the validation window, chi-square at the same level)";
  return rule;
}

}  // namespace

std::vector<std::string> parameters_at_bounds(std::span<const Parameter> params, std::span<const double> values,
                                              std::span<const std::string> owners) {
  std::vector<std::string> out;
  for (std::size_t i = 0; i < params.size(); ++i) {
    const Parameter& p = params[i];
    if (p.lower == p.upper) continue;  // held there, not pushed
    // Within 1 % of the bound's own size; a bound of zero (no negative drag) only when the fit sits on it, as a
    // bounded solver leaves a parameter it pushed there.
    const auto near = [&](double bound) {
      const double tolerance = bound == 0.0 ? kOnZeroBound : kAtBoundFraction * std::abs(bound);
      return std::isfinite(bound) && std::abs(values[i] - bound) <= tolerance;
    };
    const bool lower = near(p.lower), upper = near(p.upper);
    if (!lower && !upper) continue;
    char text[240];
    std::snprintf(text, sizeof text,
                  "%s %s = %.6g %s is at its %s bound %g: the data pushed it to the edge of its range",
                  owners[i].c_str(), p.name.c_str(), values[i], p.unit.c_str(), lower ? "lower" : "upper",
                  lower ? p.lower : p.upper);
    out.push_back(text);
  }
  return out;
}

FTest validation_f_test(double rss_before, double rss_after, std::size_t added, std::size_t parameters, double n_eff) {
  FTest out;
  const double q = static_cast<double>(std::max<std::size_t>(added, 1));
  const double denominator_dof = n_eff - static_cast<double>(parameters);
  if (!(rss_after < rss_before) || !(denominator_dof >= 1.0) || !(rss_after > 0.0)) return out;
  out.statistic = ((rss_before - rss_after) / q) / (rss_after / denominator_dof);
  out.p_value = boost::math::cdf(boost::math::complement(boost::math::fisher_f(q, denominator_dof), out.statistic));
  return out;
}

double effective_samples(std::span<const double> x, std::size_t max_lag) {
  const double n = static_cast<double>(x.size());
  if (x.size() < 2) return n;
  const std::vector<double> rho = autocorrelation(x, std::min(max_lag, x.size() - 1));
  double sum = 0.0;
  for (std::size_t k = 1; k < rho.size() && rho[k] > 0.0; ++k) sum += rho[k];
  return std::clamp(n / (1.0 + 2.0 * sum), 1.0, n);
}

FTest velocity_gain_test(std::span<const double> block_gains) {
  if (block_gains.size() < 2) return {};
  const double n = static_cast<double>(block_gains.size());
  double mean = 0.0;
  for (double g : block_gains) mean += g;
  mean /= n;
  double variance = 0.0;
  for (double g : block_gains) variance += (g - mean) * (g - mean);
  variance /= n - 1.0;
  const double n_eff = effective_samples(block_gains, block_gains.size() / 2);
  if (!(mean > 0.0) || n_eff < 2.0) return {};
  if (!(variance > 0.0)) return {std::numeric_limits<double>::infinity(), 0.0};
  const double statistic = mean / std::sqrt(variance / n_eff);
  return {statistic, boost::math::cdf(boost::math::complement(boost::math::students_t(n_eff - 1.0), statistic))};
}

std::string_view diagnose_spelling(VelocitySource velocity) {
  switch (velocity) {
    case VelocitySource::reference:
      return "reference";
    case VelocitySource::eq12:
      return "imu";
    case VelocitySource::filter:
      return "filter";
  }
  return "?";
}

estimator::DragVelocityConfig filter_config(const Signals& signals, const DiagnoseOptions& options) {
  estimator::DragVelocityConfig config;
  const estimator::Windows windows = estimator::resolve_windows(signals.t, options.train, options.validate);
  const Range train = range_of(signals, windows.train);
  // What no rigid-body model of the flight explains from one block to the next: the levelled horizontal specific
  // force of the filter's block means above the manoeuvres' band (noise, what vibration the blocks leave), over the
  // training window.
  const std::size_t block = identification_block(signals.rate_hz);
  const std::size_t first = train.first / block, last = (train.first + train.count) / block;
  if (last < first + 2) return config;
  const std::vector<estimator::ImuSample> means = block_means(signals.t, signals.gyro, signals.accel, block, last);
  const Eigen::Matrix3d level = level_rotation(signals);
  double sum = 0.0;
  for (int axis = 0; axis < 2; ++axis) {
    std::vector<double> f(last - first);
    for (std::size_t j = first; j < last; ++j) f[j - first] = (level * means[j].accel)[axis];
    std::vector<double> slow = f;
    zero_phase_lowpass(slow, kManoeuvreBandHz, signals.rate_hz / static_cast<double>(block));
    for (std::size_t k = 0; k < f.size(); ++k) sum += (f[k] - slow[k]) * (f[k] - slow[k]);
  }
  const double rms = std::sqrt(sum / static_cast<double>(2 * (last - first)));
  if (std::isfinite(rms)) config.accel_noise = std::max(config.accel_noise, rms);
  return config;
}

double use_filter(ModelSetup& setup, const Signals& signals, const DiagnoseOptions& options) {
  setup.velocity = VelocitySource::filter;
  setup.filter = filter_config(signals, options);
  setup.filter_block = identification_block(signals.rate_hz);
  const double nyquist = 0.5 * signals.rate_hz / static_cast<double>(setup.filter_block);
  setup.lowpass_hz = options.lowpass_hz > 0.0 ? std::min(options.lowpass_hz, nyquist) : nyquist;
  return setup.lowpass_hz;
}

namespace {

// The model's setup from the options: the velocity source (with the filter, its band limit) and the bands the
// residual is not fitted in. `options` becomes what the search runs with.
ModelSetup set_up_model(const Signals& signals, DiagnoseOptions& options) {
  ModelSetup setup;
  setup.base = options.model;
  setup.velocity = options.velocity.value_or(signals.reference ? VelocitySource::reference : VelocitySource::filter);
  if (setup.velocity == VelocitySource::filter) options.lowpass_hz = use_filter(setup, signals, options);
  if (options.lowpass_hz != 0.0) {
    // Above the band limit the residual holds nothing to fit and no line to report.
    options.ignore_bands.emplace_back(options.lowpass_hz, std::numeric_limits<double>::infinity());
  }
  setup.axes = options.axes;
  setup.signals = &signals;
  setup.ignore_bands = options.ignore_bands;
  setup.lowpass_hz = options.lowpass_hz;
  return setup;
}

// What every part of the search reads: the data, the options as the search runs them, the model's setup and the
// windows. `setup` changes only while the base is fitted (fit_plausible_base narrows its lever-arm or drag bound).
struct Search {
  const estimator::ImuSeries& series;
  const Signals& signals;
  const DiagnoseOptions& options;
  const ModelSetup& setup;
  estimator::Windows windows;
  Range train, validation;
  std::size_t span_lag;     // kCorrelationSpanS in samples: how far the effective sample count looks
  bool judged_by_velocity;  // with the reference; from the IMU alone a model is judged by the filter's likelihood
  // With the reference: the gyro's bias against its attitude on the validation window (gyro_bias's test).
  std::optional<GyroAgainstReference> gyro_validation{};
  std::chrono::steady_clock::time_point started{};

  // Called from the fitting threads: options.progress must be thread-safe.
  void report_progress(int step, std::string_view candidate, bool finished, std::size_t done, std::size_t total) const {
    if (!options.progress) return;
    options.progress({step, std::string(candidate), finished, done, total,
                      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count()});
  }
};

// The search over the windows asked for; throws when they hold too few samples.
Search open_search(const estimator::ImuSeries& series, const Signals& signals, const DiagnoseOptions& options,
                   const ModelSetup& setup) {
  const estimator::Windows windows = estimator::resolve_windows(signals.t, options.train, options.validate);
  estimator::require_trainable(windows.train);
  const Range train = range_of(signals, windows.train), validation = range_of(signals, windows.validate);
  // analyse_residual's minimum, and enough to fit anything.
  constexpr std::size_t kMinSamples = 64;
  if (train.count < kMinSamples || validation.count < kMinSamples)
    throw std::invalid_argument("diagnose: the training and validation windows need at least 64 samples each");
  const std::size_t span_lag = static_cast<std::size_t>(std::lround(kCorrelationSpanS * sample_rate_hz(signals.t)));
  return Search{.series = series,
                .signals = signals,
                .options = options,
                .setup = setup,
                .windows = windows,
                .train = train,
                .validation = validation,
                .span_lag = span_lag,
                .judged_by_velocity = setup.velocity == VelocitySource::reference};
}

// What was asked: the data, the model, the windows and the rule; and a warning on eq. (12)'s drift.
Diagnosis describe_request(const Search& search) {
  const DiagnoseOptions& options = search.options;
  Diagnosis out;
  out.session = options.session;
  out.model = options.model == ModelKind::paper ? "paper" : "full";
  for (int axis : search.setup.axes) out.axes.push_back(axis_name(axis));
  out.velocity_source = std::string(diagnose_spelling(search.setup.velocity));
  out.train_start = search.windows.train.start, out.train_end = search.windows.train.end;
  out.validate_start = search.windows.validate.start, out.validate_end = search.windows.validate.end;
  out.significance_rule = describe_rule(options, search.judged_by_velocity);
  if (search.setup.velocity == VelocitySource::eq12) {
    if (auto drift = estimator::eq12_drift_warning(search.series, search.signals.level_mounting, search.windows.train))
      out.warnings.push_back(std::move(*drift));
  }
  return out;
}

// The model as the live estimator will run it, what it does for the velocity (with a reference) or how likely the
// filter finds the accelerometer with it (from the IMU alone), and whether it is plausible.
// `flown_as`: the model users would fly instead, for a model whose last effect the live estimator does not run (a
// vibration line is noise to it): its velocity and likelihood are that model's, not those of a filter told the
// residual it leaves is smaller than what it will be given.
void judge(const Search& search, const Model& model, State& state, const State* flown_as = nullptr) {
  state.params = live_params(model, state.fit.values, state.fit.std_errors);
  record_fit(state.params, model, state.fit.values, search.train, search.validation);
  if (flown_as != nullptr) {
    state.summary.velocity = flown_as->summary.velocity;
    state.summary.likelihood = flown_as->summary.likelihood;
  } else {
    state.summary.velocity = estimator::score_velocity(search.series, state.params, search.windows,
                                                       search.options.validation_on_other_flights);
    // The filter's likelihood judges what the filter error method fitted (its process noise with the model). Eq. (12)'s
    // fit tunes no filter: the likelihood of its models would be that of a filter at its default noise, judging a
    // model fitted to another velocity (it refused eq. (12)'s true linear drag on seed 9 of effects-sweep).
    if (!search.judged_by_velocity && search.setup.velocity == VelocitySource::filter)
      state.summary.likelihood = estimator::filter_log_likelihood(search.series, state.params, search.windows);
  }
  state.summary.implausible.clear();
  state.implausible_limits.clear();
  for (const estimator::Implausibility& i : estimator::check_plausibility(state.params.full, search.options.limits)) {
    state.summary.implausible.push_back(i.message);
    state.implausible_limits.push_back(i.limit);
  }
}

// The base model alone within the setup's lever-arm bound, fitted on the training window and judged.
State fit_base(const Search& search) {
  const Model base(search.signals, search.setup);
  State state = settle(base, fit(base, base.base_start(search.train), search.train, 50, FitStop::cost, cores()),
                       search.train, search.validation);
  judge(search, base, state);
  return state;
}

// Whether a component of the base's lever arm sits on the setup's bound.
bool lever_arm_at_bound(const Search& search, const State& current) {
  const double bound = search.setup.lever_arm_bound;
  const std::vector<Parameter> base = Model(search.signals, search.setup).parameters();
  for (std::size_t i = 0; i < base.size() && i < current.fit.values.size(); ++i) {
    if (base[i].unit == "m" && std::abs(std::abs(current.fit.values[i]) - bound) <= kAtBoundFraction * bound)
      return true;
  }
  return false;
}

// A base no airframe has is not carried on: it is fitted again with its lever arm inside the table (a box
// inscribed in the table's sphere for the 3-D model), from the same start. `setup` is the one `search` reads.
void refit_base_inside_table(const Search& search, ModelSetup& setup, State& current,
                             std::vector<std::string>& warnings) {
  const DiagnoseOptions& options = search.options;
  std::string was = current.summary.implausible.front();
  setup.lever_arm_bound =
      options.model == ModelKind::full ? options.limits.lever_arm / std::sqrt(3.0) : options.limits.lever_arm;
  current = fit_base(search);
  char text[480];
  std::snprintf(text, sizeof text,
                "the base model's first fit was implausible (%s); it was fitted again with each lever-arm component "
                "within +-%.3g m",
                was.c_str(), setup.lever_arm_bound);
  warnings.emplace_back(text);
  if (lever_arm_at_bound(search, current)) {
    // Pushed to the edge of the box, the lever arm is not placed by these data either: the IMU is taken at the
    // mass centre, the assumption that claims least.
    setup.lever_arm_bound = 0.0;
    current = fit_base(search);
    warnings.emplace_back(
        "inside the table the lever arm went to the edge of its range: the data do not place it, and it is held at "
        "the mass centre (0, 0, 0)");
  }
}

// The base model the search starts from: fitted, and fitted again inside the plausibility table when its lever arm
// or the paper model's mu is beyond it (saying so in `warnings`).
State fit_plausible_base(const Search& search, ModelSetup& setup, std::vector<std::string>& warnings) {
  State current = fit_base(search);
  const bool lever_arm_implausible = std::find(current.implausible_limits.begin(), current.implausible_limits.end(),
                                               "lever_arm") != current.implausible_limits.end();
  if (lever_arm_implausible) refit_base_inside_table(search, setup, current, warnings);
  // The paper model's mu past the table (a drag no multirotor cruises against): fitted again within it, as the lever
  // arm; at the table's edge it is flagged there (at_bounds) for what it is.
  const auto& limits = current.implausible_limits;
  if (std::find(limits.begin(), limits.end(), "drag_quadratic") != limits.end() &&
      search.options.model == ModelKind::paper) {
    setup.drag_bound = search.options.limits.drag_quadratic;
    char text[480];
    std::snprintf(text, sizeof text,
                  "the base model's first fit was implausible (%s); it was fitted again with mu within [0, %g] 1/m",
                  current.summary.implausible.front().c_str(), setup.drag_bound);
    warnings.emplace_back(text);
    current = fit_base(search);
  }
  return current;
}

// The base model in the report: its fit, zero velocity's error beside it (with a reference), its residual.
void describe_base(const Search& search, const State& current, Diagnosis& out) {
  const Model base_model(search.signals, search.setup);
  out.base = current.summary;
  if (search.series.reference)
    out.zero_velocity = estimator::zero_velocity_scores(search.series, current.params.full.mounting, search.windows);
  out.base_residual = analyse(base_model, current, search.validation, search.options);
}

// One step of the search: the model it starts from, and what each of its candidates is tried with.
struct StepContext {
  const Search& search;
  int step;  // from 0
  const State& current;
  std::vector<std::string> in_model;  // the current model's effects, by name
  bool judge_tilt;                    // whether a candidate is refused for tilting past 90 deg
};

StepContext open_step(const Search& search, int step, const State& current) {
  std::vector<std::string> in_model = names_of(current.effects);
  // Only judged when the attitude comes from the gyro, and only if the current model's attitude is a flight's.
  const bool judge_tilt = search.setup.velocity == VelocitySource::eq12 &&
                          largest_tilt(Model(search.signals, search.setup, current.effects), current.fit.values,
                                       search.train, search.validation) <= kMaxFlightTiltRad;
  return {search, step, current, std::move(in_model), judge_tilt};
}

// The effects of a candidate model: the current model's, the effects `effect` needs (a compound candidate; named in
// trial.with), then the effect itself.
std::vector<const Effect*> candidate_effects(const StepContext& step, const Effect& effect, CandidateTrial& trial) {
  std::vector<const Effect*> effects = step.current.effects;
  for (const std::string& needed : effect.needs(step.search.setup, step.in_model)) {
    effects.push_back(find_effect(needed));
    trial.with.push_back(needed);
  }
  effects.push_back(&effect);
  return effects;
}

// Appends each new effect's own start to `start` (the current values), and scans the drag the new effects add when
// the velocity comes from the filter. Why an effect cannot start on these data, or nullopt.
std::optional<std::string> add_effect_starts(const StepContext& step, const Model& model,
                                             const std::vector<const Effect*>& effects, std::vector<double>& start) {
  const Search& search = step.search;
  for (std::size_t i = start.size(); i < model.parameters().size(); ++i) start.push_back(model.parameters()[i].initial);
  const std::span<const double> train_t(search.signals.t.data() + search.train.first, search.train.count);
  const StartContext context{search.setup, train_t, step.current.train_residual};
  std::vector<std::size_t> drag;
  for (std::size_t e = step.current.effects.size(); e < effects.size(); ++e) {
    const auto own = std::span<double>(start).subspan(model.effect_offset(e), model.effect_size(e));
    if (auto why = effects[e]->start(context, own)) return why;
    if (search.setup.velocity == VelocitySource::filter && effects[e]->adds_drag()) {
      for (std::size_t i = 0; i < model.effect_size(e); ++i) drag.push_back(model.effect_offset(e) + i);
    }
  }
  if (!drag.empty()) model.scan_drag_start(start, drag, search.train);
  return std::nullopt;
}

// Where the candidate's fit starts: `start`, or one of the effect's other starts (Effect::more_starts).
std::vector<double> screened_start(const Search& search, const Effect& effect,
                                   const std::vector<const Effect*>& effects, const Model& model,
                                   const std::vector<double>& start) {
  const std::size_t own_offset = model.effect_offset(effects.size() - 1);
  // Several starting points: each is screened by a few iterations, at once, on a model of its own (a model's
  // caches are not shared between threads); the one with the lowest training cost then (the earlier on a tie)
  // is fitted to convergence. The basins the starts are for differ from the first iterations on.
  std::vector<std::vector<double>> starts{start};
  for (const std::vector<double>& more : effect.more_starts(std::span<const double>(start).subspan(own_offset))) {
    starts.push_back(start);
    std::copy(more.begin(), more.end(), starts.back().begin() + static_cast<std::ptrdiff_t>(own_offset));
  }
  std::vector<double> chosen_start = starts.front();
  if (starts.size() > 1) {
    constexpr int kScreenIterations = 8;
    std::vector<std::future<FitOutcome>> screened;
    for (std::size_t i = 0; i < starts.size(); ++i) {
      screened.push_back(std::async(std::launch::async, [&, i] {
        const Model own(search.signals, model.setup(), effects);
        return fit(own, starts[i], search.train, kScreenIterations);
      }));
    }
    double lowest = std::numeric_limits<double>::infinity();
    for (std::future<FitOutcome>& s : screened) {
      FitOutcome o = s.get();
      if (o.convergence.back() < lowest) lowest = o.convergence.back(), chosen_start = std::move(o.values);
    }
  }
  return chosen_start;
}

// The new effects' parameters (from `first` on) to hold at zero when `values` are implausible: each whose own value,
// set to zero, clears a per-axis limit they exceed, provided its effect keeps a free parameter. A value past the
// table on one axis (a drag of 2.3 1/s on y while the time offset is missing) is not what the data place there; the
// effect may still be there on the others. Empty when no such parameter clears it.
std::vector<std::size_t> axes_to_hold(const Search& search, const Model& model, const std::vector<double>& values,
                                      std::size_t first) {
  const auto per_axis_exceeded = [&](const std::vector<double>& v) {
    const std::vector<estimator::Implausibility> all =
        estimator::check_plausibility(live_params(model, v).full, search.options.limits);
    return std::count_if(all.begin(), all.end(), [](const estimator::Implausibility& i) { return i.per_axis; });
  };
  const auto exceeded = per_axis_exceeded(values);
  std::vector<std::size_t> hold;
  for (std::size_t e = 0; e < model.effects().size(); ++e) {
    if (model.effect_offset(e) < first) continue;
    std::vector<std::size_t> clears;
    std::size_t free = 0;
    for (std::size_t i = model.effect_offset(e); i < model.effect_offset(e + 1); ++i) {
      if (model.inert(i)) continue;
      ++free;
      std::vector<double> zeroed = values;
      zeroed[i] = 0.0;
      if (per_axis_exceeded(zeroed) < exceeded) clears.push_back(i);
    }
    if (!clears.empty() && clears.size() < free) hold.insert(hold.end(), clears.begin(), clears.end());
  }
  return hold;
}

// ModelSetup::held_at_zero's names of `hold` (parameters of `model`), appended to `names`, and a line saying what
// each was fitted to (`values`).
std::string hold_names(const Model& model, std::span<const double> values, const std::vector<std::size_t>& hold,
                       std::vector<std::string>& names) {
  std::string note;
  for (std::size_t i : hold) {
    const Parameter& p = model.parameters()[i];
    names.push_back(held_name(owner_of(model, i), p.name));
    char text[200];
    std::snprintf(text, sizeof text, "%s%s held at 0 (its fit, %.4g %s, went past the plausibility table)",
                  note.empty() ? "" : "; ", p.name.c_str(), values[i], p.unit.c_str());
    note += text;
  }
  return note + ", and the rest fitted again without it";
}

// What `params` exceed of the plausibility table beyond what `before` already does: a limit the model before exceeds
// (its base, say) is flagged there and would otherwise block every step after it.
std::vector<estimator::Implausibility> made_implausible(const Search& search, const estimator::FullModelParams& params,
                                                        const State& before) {
  const std::vector<std::string>& already = before.implausible_limits;
  std::vector<estimator::Implausibility> out;
  for (estimator::Implausibility& i : estimator::check_plausibility(params, search.options.limits)) {
    if (std::find(already.begin(), already.end(), i.limit) == already.end()) out.push_back(std::move(i));
  }
  return out;
}

// Why a fitted candidate is refused whatever its gain (it tilts past a flight's attitude, it is implausible, or,
// judged by the flight, the data do not determine the parameters from `offset` on), or nullopt.
std::optional<std::string> refused_fit(const StepContext& step, const Model& model, const FitOutcome& best,
                                       std::size_t offset) {
  const Search& search = step.search;
  if (auto why = step.judge_tilt ? unflyable(model, best.values, search.train, search.validation) : std::nullopt)
    return why;
  const std::vector<estimator::Implausibility> implausible =
      made_implausible(search, live_params(model, best.values).full, step.current);
  if (!implausible.empty()) {
    std::string why = "implausible: " + implausible.front().message;
    for (std::size_t i = 1; i < implausible.size(); ++i) why += "; " + implausible[i].message;
    return why;
  }
  return search.options.flight_rules ? undetermined(model, best, offset) : std::nullopt;
}

// The fitted candidate as a model: judged (flown as the current model when the live estimator does not run its
// effect), with its errors and the significance rule's F-test against the current model written into `trial`.
State measure_candidate(const StepContext& step, const Effect& effect, const Model& model, FitOutcome best,
                        CandidateTrial& trial) {
  const Search& search = step.search;
  const State& current = step.current;
  State candidate = settle(model, std::move(best), search.train, search.validation);
  judge(search, model, candidate, effect.live_refusal() ? &current : nullptr);
  trial.rmse_train = candidate.summary.rmse_train;
  trial.rmse_validation = candidate.summary.rmse_validation;
  if (candidate.summary.velocity) trial.velocity_validation = candidate.summary.velocity->validation.horizontal;
  if (candidate.summary.likelihood) trial.likelihood_validation = candidate.summary.likelihood->validation;
  double n_eff = 0.0;
  for (const std::vector<double>& r : candidate.validation_residual) n_eff += effective_samples(r, search.span_lag);
  // Free parameters: one the current model held at zero and the candidate fits again is one more, a new one held one
  // fewer.
  const std::size_t free = candidate.summary.free_parameters;
  const FTest test =
      validation_f_test(sum_of_squares(current.validation_residual), sum_of_squares(candidate.validation_residual),
                        free - std::min(free, current.summary.free_parameters), free, n_eff);
  trial.statistic = test.statistic;
  trial.p_value = test.p_value;
  // A first drag, with the reference: the current model gives the user no velocity (zero velocity's, its note says),
  // and whether the drag is there shows best in the velocity it gives.
  const auto gives_velocity = [](const State& s) { return s.summary.velocity && s.summary.velocity->note.empty(); };
  if (search.judged_by_velocity && search.options.flight_rules && effect.adds_drag() && !gives_velocity(current) &&
      gives_velocity(candidate))
    trial.velocity_test_p = velocity_gain_test(candidate.summary.velocity->validation_gain_over_zero).p_value;
  // A gyro bias measured against the reference's attitude: whether the validation window shows it too (not under
  // --residual-only, which judges by the specific force alone, like the velocity's test).
  if (search.options.flight_rules && search.setup.reference_gyro_bias && search.gyro_validation &&
      effect.name() == "gyro_bias")
    trial.attitude_test_p = search.gyro_validation->p_value;
  return candidate;
}

// One candidate: the current model plus `effect`, fitted on the training window and tested on the validation
// window; or the reason it was not tried.
std::pair<CandidateTrial, std::optional<State>> try_candidate(const StepContext& step, const Effect& effect,
                                                              unsigned jacobian_threads) {
  const Search& search = step.search;
  CandidateTrial trial;
  trial.effect = std::string(effect.name());
  if (auto why = effect.why_not(search.setup, step.in_model)) {
    trial.skipped = *why;
    return {trial, std::nullopt};
  }
  try {
    // The effects it needs first (a compound candidate), then the effect itself.
    const std::vector<const Effect*> effects = candidate_effects(step, effect, trial);
    // The current model's axes held at zero stay held: the candidate is that model plus the effect (release_holds
    // frees them once a step is taken).
    ModelSetup setup = search.setup;
    setup.held_at_zero = step.current.held_at_zero;
    const Model model(search.signals, setup, effects);
    // Warm start: the current values, then each new effect's own start.
    std::vector<double> start = step.current.fit.values;
    const std::size_t offset = start.size();
    if (auto why = add_effect_starts(step, model, effects, start)) {
      trial.skipped = *why;
      return {trial, std::nullopt};
    }
    FitOutcome best = fit(model, screened_start(search, effect, effects, model, start), search.train, 50, FitStop::cost,
                          jacobian_threads);
    std::optional<std::string> why = refused_fit(step, model, best, offset);
    // Past the table on some of the new effects' axes: fitted again with those held at zero (a value the current
    // model has placed is not given up for a new effect's sake), and judged as that.
    std::optional<Model> held;
    if (why && why->starts_with("implausible")) {
      if (const std::vector<std::size_t> hold = axes_to_hold(search, model, best.values, offset); !hold.empty()) {
        trial.held = hold_names(model, best.values, hold, trial.held_at_zero);
        setup.held_at_zero.insert(setup.held_at_zero.end(), trial.held_at_zero.begin(), trial.held_at_zero.end());
        held.emplace(search.signals, setup, effects);
        best = fit(*held, best.values, search.train, 50, FitStop::cost, jacobian_threads);
        if (auto still = refused_fit(step, *held, best, offset))
          *why += "; and with " + trial.held + ": " + *still;
        else
          why.reset();
      }
    }
    if (why) {
      trial.skipped = *why;
      return {trial, std::nullopt};
    }
    // Two statements: `trial` is copied into the pair only once measure_candidate has filled it.
    State candidate = measure_candidate(step, effect, held ? *held : model, std::move(best), trial);
    candidate.held_at_zero = std::move(setup.held_at_zero);
    return {trial, std::move(candidate)};
  } catch (const std::exception& e) {
    trial.skipped = std::string("failed to fit: ") + e.what();
    return {trial, std::nullopt};
  }
}

// The candidates of a step so far, in library order: what each gave, and each tried one's fitted model.
struct Trials {
  std::vector<CandidateTrial> trials;
  std::vector<std::optional<State>> fitted;
  std::size_t tried = 0;  // not skipped; the significance level is shared among them (set by apply_rules)
};

// Fits `untried` on every core at once, kept in library order so that the outcome does not depend on which
// finishes first.
void fit_candidates_in_parallel(const StepContext& step, const std::vector<const Effect*>& untried, Trials& out) {
  const std::size_t first = out.trials.size();
  out.trials.resize(first + untried.size());
  out.fitted.resize(first + untried.size());
  std::atomic<std::size_t> next{0}, done{0};
  const std::size_t threads = std::min<std::size_t>(cores(), untried.size());
  // The cores the candidates leave idle (a step with fewer candidates than cores) share each fit's Jacobian.
  const auto jacobian_threads = static_cast<unsigned>(cores() / std::max<std::size_t>(threads, 1));
  estimator::on_threads(threads, [&](std::size_t) {
    for (std::size_t i = next++; i < untried.size(); i = next++) {
      step.search.report_progress(step.step + 1, untried[i]->name(), false, done.load(), untried.size());
      std::tie(out.trials[first + i], out.fitted[first + i]) = try_candidate(step, *untried[i], jacobian_threads);
      step.search.report_progress(step.step + 1, untried[i]->name(), true, ++done, untried.size());
    }
  });
}

// What a step must beat: the current model's validation RMSE and what users fly with, before this step: the
// velocity a step must lower, or the likelihood it must raise.
struct BeforeStep {
  double rmse_validation = 0.0;
  std::optional<double> velocity, likelihood, flight;
};

BeforeStep before_step(const State& current, bool judged_by_velocity) {
  BeforeStep before;
  before.rmse_validation = current.summary.rmse_validation;
  before.velocity =
      current.summary.velocity ? std::optional(current.summary.velocity->validation.horizontal) : std::nullopt;
  before.likelihood = current.summary.likelihood ? std::optional(current.summary.likelihood->validation) : std::nullopt;
  before.flight = flight_score(before.velocity, before.likelihood, judged_by_velocity);
  return before;
}

// A test beside the specific-force residual's rules: its p-value where it ran, and what it saw.
struct BesideTheResidual {
  const char* name;
  std::optional<double> p;
  std::string seen{};
};

// Judges every candidate so far by the significance rule, at the level shared among all those tried, and names the
// rule that rejects each one that fails.
void apply_rules(const Search& search, const BeforeStep& before, Trials& out) {
  const DiagnoseOptions& options = search.options;
  out.tried = static_cast<std::size_t>(
      std::count_if(out.trials.begin(), out.trials.end(), [](const CandidateTrial& t) { return t.skipped.empty(); }));
  const double level = options.significance / static_cast<double>(std::max<std::size_t>(out.tried, 1));
  for (CandidateTrial& t : out.trials) {
    if (!t.skipped.empty()) continue;
    const bool improves = t.rmse_validation <= (1.0 - options.min_improvement) * before.rmse_validation;
    const bool passes_f_test = t.p_value < level;
    // The velocity or likelihood rule: a lower specific-force residual is not worth a worse velocity.
    const std::optional<double> score =
        flight_score(t.velocity_validation, t.likelihood_validation, search.judged_by_velocity);
    const bool no_worse_flown =
        !options.flight_rules || !(before.flight && score) || flies_no_worse(*score, *before.flight, options);
    // The tests beside the residual's, where they ran (one at most: the velocity's for a first drag, which the
    // velocity it gives shows beyond chance; the reference attitude's for a gyro bias, which the specific force
    // hardly shows): each admits what it shows.
    std::array<BesideTheResidual, 2> beside = {
        {{"the reference attitude's test", t.attitude_test_p}, {"the velocity's test", t.velocity_test_p}}};
    char why[400];
    if (t.attitude_test_p) {
      const Eigen::Vector3d& b = *search.setup.reference_gyro_bias;
      std::snprintf(why, sizeof why,
                    "the gyro reads (%.4f, %.4f, %.4f) rad/s beyond the reference's turn (training window), p = %.3g "
                    "on the validation window",
                    b.x(), b.y(), b.z(), *t.attitude_test_p);
      beside[0].seen = why;
    }
    if (t.velocity_test_p) {
      std::snprintf(why, sizeof why, "validation velocity RMSE %.3f m/s against zero velocity's %.3f, p = %.3g",
                    *t.velocity_validation, *before.velocity, *t.velocity_test_p);
      beside[1].seen = why;
    }
    const auto shows = [&](const BesideTheResidual& b) { return b.p && *b.p < level; };
    const auto admitting = std::find_if(beside.begin(), beside.end(), shows);
    const bool residual_shows_it = improves && passes_f_test;
    const bool shown = residual_shows_it || admitting != beside.end();
    t.significant = shown && no_worse_flown;
    t.rejected_by.clear();
    t.admitted_by.clear();
    if (t.significant && !residual_shows_it) {
      std::snprintf(why, sizeof why, "%s: %s, below %.3g (the specific-force residual %+.2f %%)", admitting->name,
                    admitting->seen.c_str(), level, 100.0 * (t.rmse_validation / before.rmse_validation - 1.0));
      t.admitted_by = why;
    }
    if (t.significant) continue;
    // Shown by one test or another, and refused for how it flies: that rule is the reason, whichever test showed it.
    if (shown && search.judged_by_velocity) {
      std::snprintf(why, sizeof why,
                    "velocity rule: validation velocity RMSE %.3f -> %.3f m/s (a step must not raise it)",
                    *before.velocity, *t.velocity_validation);
      t.rejected_by = why;
    } else if (shown) {
      std::snprintf(why, sizeof why,
                    "likelihood rule: the filter's validation log-likelihood %.4f -> %.4f per measurement (a step "
                    "must not lower it)",
                    *before.likelihood, *t.likelihood_validation);
      t.rejected_by = why;
    } else if (!improves) {
      std::snprintf(why, sizeof why, "minimum-gain rule: validation RMSE %+.2f %% (needs at least -%g %%)",
                    100.0 * (t.rmse_validation / before.rmse_validation - 1.0), 100.0 * options.min_improvement);
      t.rejected_by = why;
    } else if (!passes_f_test) {
      std::snprintf(why, sizeof why, "F-test: p = %.3g, not below %.3g (%g / %zu candidates)", t.p_value, level,
                    options.significance, out.tried);
      t.rejected_by = why;
    }
    for (const BesideTheResidual& b : beside) {
      if (!b.p || shows(b) || t.rejected_by.empty()) continue;
      std::snprintf(why, sizeof why, "; nor %s: p = %.3g, not below %.3g", b.name, *b.p, level);
      t.rejected_by += why;
    }
  }
}

// Fits and judges every candidate of a step. Single candidates first. A compound one (an effect with what it needs,
// Effect::needs) only when no single candidate passes the rules: the effects it brings along are candidates of
// their own, and one of them that passes alone is the simpler explanation.
Trials fit_and_judge_candidates(const StepContext& step) {
  const Search& search = step.search;
  std::vector<const Effect*> singles, compounds;
  for (const auto& effect : effect_library()) {
    if (std::find(step.current.effects.begin(), step.current.effects.end(), effect.get()) != step.current.effects.end())
      continue;
    (effect->needs(search.setup, step.in_model).empty() ? singles : compounds).push_back(effect.get());
  }
  Trials out;
  const BeforeStep before = before_step(step.current, search.judged_by_velocity);
  fit_candidates_in_parallel(step, singles, out);
  apply_rules(search, before, out);
  const bool single_passes =
      std::any_of(out.trials.begin(), out.trials.end(), [](const CandidateTrial& t) { return t.significant; });
  if (!single_passes) {
    fit_candidates_in_parallel(step, compounds, out);
    apply_rules(search, before, out);
  } else {
    for (const Effect* e : compounds) {
      CandidateTrial trial;
      trial.effect = std::string(e->name());
      trial.with = e->needs(search.setup, step.in_model);
      trial.skipped = "a compound candidate, tried only when no single candidate passes the rules";
      out.trials.push_back(std::move(trial));
      out.fitted.emplace_back();
    }
  }
  return out;
}

// Best first, the skipped after, in library order. Judged by the flight, the step taken is among the candidates
// that pass every rule and fly best (within flight_tolerance of the best validation velocity or likelihood): the
// lowest specific-force residual is no reason to fly a worse velocity, nor to stop when that candidate fails the
// flight's rule while another passes. Among those, and otherwise, the lowest validation residual.
std::vector<std::size_t> rank_candidates(const Search& search, const std::vector<CandidateTrial>& trials) {
  const std::vector<bool> flies_best = flying_best(trials, search.judged_by_velocity, search.options);
  std::vector<std::size_t> order(trials.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    const bool a_tried = trials[a].skipped.empty(), b_tried = trials[b].skipped.empty();
    if (a_tried != b_tried) return a_tried;
    if (!a_tried) return false;
    if (flies_best[a] != flies_best[b]) return static_cast<bool>(flies_best[a]);
    return trials[a].rmse_validation < trials[b].rmse_validation;
  });
  return order;
}

// A step's model with axes held at zero, fitted again with them free now that the step's effect is in (a drag past
// the table on one axis until the time offset was in): kept when it is plausible and flies and fits no worse, with
// a line saying so. A drag released starts from the scan a new drag starts from.
std::optional<State> release_holds(const Search& search, const State& held, std::string& note) {
  if (held.held_at_zero.empty() || held.effects.back()->live_refusal()) return std::nullopt;
  const Model model(search.signals, search.setup, held.effects);
  std::vector<double> start = held.fit.values;
  std::vector<std::size_t> released, drag;
  for (std::size_t i = model.base_size(); i < start.size(); ++i) {
    const std::string owner = owner_of(model, i);
    if (!holds(held.held_at_zero, owner, model.parameters()[i].name)) continue;
    released.push_back(i);
    if (find_effect(owner)->adds_drag()) drag.push_back(i);
  }
  if (!drag.empty() && search.setup.velocity == VelocitySource::filter)
    model.scan_drag_start(start, drag, search.train);
  State out =
      settle(model, fit(model, start, search.train, 50, FitStop::cost, cores()), search.train, search.validation);
  judge(search, model, out);
  if (!made_implausible(search, out.params.full, held).empty()) return std::nullopt;
  const std::optional<double> before = before_step(held, search.judged_by_velocity).flight;
  const std::optional<double> after = before_step(out, search.judged_by_velocity).flight;
  if ((before && after && !flies_no_worse(*after, *before, search.options)) ||
      out.summary.rmse_validation > held.summary.rmse_validation)
    return std::nullopt;
  for (std::size_t i : released) {
    char text[160];
    std::snprintf(text, sizeof text, "%s%s %s fitted again with the step's effect in: %.4g %s",
                  note.empty() ? "" : "; ", owner_of(model, i).c_str(), model.parameters()[i].name.c_str(),
                  out.fit.values[i], model.parameters()[i].unit.c_str());
    note += text;
  }
  return out;
}

// One step of the greedy search from `current`: the best candidate, when it passes the rules, becomes `current` and
// out.steps' last. False when none does, with the candidates in out.last_candidates.
bool take_step(const Search& search, int step_index, State& current, Diagnosis& out) {
  Trials trials = fit_and_judge_candidates(open_step(search, step_index, current));
  const std::vector<std::size_t> order = rank_candidates(search, trials.trials);
  std::vector<CandidateTrial> sorted;
  for (std::size_t i : order) sorted.push_back(trials.trials[i]);

  if (trials.tried == 0 || !trials.trials[order.front()].significant) {
    out.last_candidates = std::move(sorted);
    return false;
  }
  Step s;
  s.effect = trials.trials[order.front()].effect;
  s.with = trials.trials[order.front()].with;
  s.rmse_train_before = current.summary.rmse_train;
  s.rmse_validation_before = current.summary.rmse_validation;
  current = std::move(*trials.fitted[order.front()]);  // judged when it was tried
  if (std::optional<State> released = release_holds(search, current, s.released)) current = std::move(*released);
  s.fit = current.summary;
  s.params = current.summary.effect_params.back();
  s.candidates = std::move(sorted);
  const Model model(search.signals, search.setup, current.effects);
  s.residual = analyse(model, current, search.validation, search.options);
  out.steps.push_back(std::move(s));
  return true;
}

// From the IMU alone a drifting accelerometer bias (a MEMS part warming up) leaves the residual flat: the filter takes
// the drifting force for a velocity that ramps. A multirotor does not hold one acceleration for tens of seconds, nor
// ramp past the speeds it cruises at (kBriskSpeed), so a significant line through the filter's own velocity across
// both windows that changes it by more than that is named as what the model lacks. A drag fitted too weak to hold
// the velocity lets it run away the same way. A flight that speeds up along a leg ramps too, by less: on real
// flights (docs/effects.md) such ramps stay within it.
void name_velocity_ramps(const Search& search, std::span<const Eigen::Vector3d> velocity, Diagnosis& out) {
  const std::size_t first = std::min(search.train.first, search.validation.first);
  const std::size_t end = std::min(velocity.size(), std::max(search.train.first + search.train.count,
                                                             search.validation.first + search.validation.count));
  const std::span<const double> t(search.signals.t.data() + first, end - first);
  const double span_s = t.back() - t.front();
  for (std::size_t i = 0; i < search.setup.axes.size(); ++i) {
    std::vector<double> v(end - first);
    for (std::size_t k = first; k < end; ++k) v[k - first] = velocity[k][search.setup.axes[i]];
    const Trend trend = fit_trend(t, v, std::min(search.span_lag, v.size() / 4));
    const VelocityRamp& ramp = out.velocity_ramps.emplace_back(VelocityRamp{
        .axis = out.axes[i],
        .span_s = span_s,
        .per_s = trend.slope,
        .std_error = trend.std_error,
        .named = trend.significant && std::abs(trend.slope * span_s) > estimator::kBriskSpeed});
    if (!ramp.named) continue;
    Unexplained u;
    u.kind = "velocity ramp";
    u.axis = ramp.axis;
    u.value = trend.slope;
    char where[320];
    std::snprintf(where, sizeof where,
                  "the filter's velocity ramps by %+.3g m/s over %.0f s (%+.3g m/s^2, %.1f standard errors), more than "
                  "a multirotor cruises at (%g m/s): a drag too weak to hold it, or an accelerometer bias that drifts "
                  "(an IMU warming up), reads so; a velocity reference would tell",
                  ramp.ramp_m_s(), span_s, trend.slope, std::abs(trend.slope) / trend.std_error,
                  estimator::kBriskSpeed);
    u.where = where;
    out.unexplained.push_back(std::move(u));
  }
}

// With a reference to score by, the filter's one-step velocity against it on the training window (PredictionScale).
void measure_prediction_scale(const Search& search, std::span<const Eigen::Vector3d> velocity, Diagnosis& out) {
  if (!search.signals.reference) return;
  const std::vector<Eigen::Vector3d>& truth = search.signals.reference->velocity_body;
  for (std::size_t i = 0; i < search.setup.axes.size(); ++i) {
    const int axis = search.setup.axes[i];
    double cross = 0.0, square = 0.0;
    for (std::size_t k = search.train.first; k < search.train.first + search.train.count && k < velocity.size(); ++k) {
      cross += velocity[k][axis] * truth[k][axis];
      square += truth[k][axis] * truth[k][axis];
    }
    if (square > 0.0 && std::isfinite(cross)) out.prediction_scale.push_back({out.axes[i], cross / square});
  }
}

// The final model, and what structure its validation residual leaves unexplained.
void describe_final(const Search& search, const State& current, Diagnosis& out) {
  out.final = current.summary;
  out.final_params = current.params;
  out.final_residual = out.steps.empty() ? out.base_residual : out.steps.back().residual;
  out.residual_white = std::all_of(out.final_residual.begin(), out.final_residual.end(),
                                   [](const ResidualAnalysis& a) { return a.white; });
  for (std::size_t i = 0; i < out.final_residual.size(); ++i) {
    for (Unexplained& u : unexplained_structure(out.final_residual[i], out.axes[i])) out.unexplained.push_back(u);
  }
  // From the IMU alone, the filter's one-step velocity: what the drag was fitted on (none without drag).
  if (search.setup.velocity != VelocitySource::filter) return;
  const Model model(search.signals, search.setup, current.effects);
  if (!model.filter_runs()) return;
  const std::vector<Eigen::Vector3d> velocity = model.inputs(current.fit.values).velocity;
  name_velocity_ramps(search, velocity, out);
  measure_prediction_scale(search, velocity, out);
}

// The plots' series: the final model's frame, with each model's prediction as measured - residual.
std::vector<AxisSeries> plot_series(const Search& search, const State& current,
                                    const AxisValues& base_validation_residual, const std::vector<std::string>& axes) {
  const Range validation = search.validation;
  const Model final_model(search.signals, search.setup, current.effects);
  const Evaluation final_eval = final_model.evaluate(current.fit.values, validation);
  std::vector<AxisSeries> series;
  for (std::size_t i = 0; i < search.setup.axes.size(); ++i) {
    AxisSeries a;
    a.axis = axes[i];
    a.t.assign(search.signals.t.begin() + static_cast<std::ptrdiff_t>(validation.first),
               search.signals.t.begin() + static_cast<std::ptrdiff_t>(validation.first + validation.count));
    a.measured = final_eval.measured[i];
    a.base_model.resize(validation.count);
    a.final_model.resize(validation.count);
    for (std::size_t k = 0; k < validation.count; ++k) {
      a.base_model[k] = a.measured[k] - base_validation_residual[i][k];
      a.final_model[k] = a.measured[k] - current.validation_residual[i][k];
    }
    series.push_back(std::move(a));
  }
  return series;
}

}  // namespace

Diagnosis run_diagnosis(const estimator::ImuSeries& series, const DiagnoseOptions& requested) {
  DiagnoseOptions options = requested;
  if (options.lowpass_hz != 0.0 && !(options.lowpass_hz > 0.0))
    throw std::invalid_argument("diagnose: the low-pass cutoff must be positive");
  const Signals signals = prepare_signals(series);
  ModelSetup setup = set_up_model(signals, options);
  if (options.max_steps < 0) throw std::invalid_argument("diagnose: the number of steps cannot be negative");
  Search search = open_search(series, signals, options, setup);
  Diagnosis out = describe_request(search);
  if (setup.velocity == VelocitySource::reference) {
    out.gyro_train = gyro_against_reference(signals, search.train.first, search.train.count);
    out.gyro_validation = gyro_against_reference(signals, search.validation.first, search.validation.count);
    // Both windows, or neither: the test needs the one, the bias the other.
    if (out.gyro_train && out.gyro_validation) {
      setup.reference_gyro_bias = out.gyro_train->bias;
      search.gyro_validation = out.gyro_validation;
    }
  }

  search.started = std::chrono::steady_clock::now();
  search.report_progress(0, "base", false, 0, 1);
  State current = fit_plausible_base(search, setup, out.warnings);
  describe_base(search, current, out);
  const AxisValues base_validation_residual = current.validation_residual;
  for (int step = 0; step < options.max_steps; ++step) {
    if (!take_step(search, step, current, out)) break;
  }
  describe_final(search, current, out);
  out.series = plot_series(search, current, base_validation_residual, out.axes);
  return out;
}

}  // namespace imubridge::diagnose
