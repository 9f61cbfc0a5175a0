#pragma once
// The greedy model search of `imubridge diagnose` (docs/effects.md): fit the base model on the training window, then
// repeatedly try every effect of the library on top of the current model, refitting everything, and add the one
// that lowers the VALIDATION error most, while it passes the significance rule; analyse the residual after each
// step and report what structure remains.
#include <cstddef>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "diagnose/diagnosis.hpp"
#include "diagnose/effects/effect.hpp"
#include "diagnose/signals.hpp"
#include "estimator/imu_series.hpp"
#include "estimator/params.hpp"
#include "identification/plausibility.hpp"

namespace imubridge::diagnose {

// Where a running diagnosis is, for a progress display.
struct DiagnoseProgress {
  int step = 0;           // 0: the base model; then the step whose candidates are being fitted
  std::string candidate;  // the effect ("base" at step 0) a thread has started or, with `finished`, finished
  bool finished = false;
  std::size_t done = 0;    // candidates of this step finished
  std::size_t total = 0;   // candidates of this step
  double elapsed_s = 0.0;  // since run_diagnosis started
};

struct DiagnoseOptions {
  ModelKind model = ModelKind::paper;
  std::optional<VelocitySource> velocity;         // default: the reference when the series has one, else the filter
  std::vector<int> axes{0, 1};                    // 0 = x, 1 = y
  std::optional<estimator::TimeWindow> train;     // default [0, 33) s, the paper's split
  std::optional<estimator::TimeWindow> validate;  // default from the end of `train` to the end of the data
  std::vector<std::pair<double, double>> ignore_bands;  // Hz: no vibration is fitted there, no line reported
  // > 0: compare model and measurement below this frequency only (docs/effects.md, "Band limit"), Hz; everything
  // above it joins the ignored bands.
  double lowpass_hz = 0.0;
  int max_steps = 8;
  // The significance rule: the F-test on the validation residual sums of squares (validation_f_test) at
  // `significance` divided by the number of candidates tried (Bonferroni), and a validation RMSE lower by at least
  // `min_improvement` (relative), so that gains too small to matter do not pile up on long flights.
  double significance = 0.01;
  double min_improvement = 0.02;
  // The rules by what users fly with (docs/effects.md, "The velocity or likelihood rule"): a step must not fly worse,
  // by the validation velocity (with the reference) or the filter's likelihood (from the IMU alone), and a candidate
  // whose parameters the data do not determine is refused. Always on but for comparisons (issue 24: a step that lowers
  // the specific-force residual while it wrecks the velocity is not a finding).
  bool flight_rules = true;
  // Of the candidates that pass every rule, take one that flies best instead of the lowest residual (--judge-by-flight).
  // Opt-in: a validation window's velocity cannot tell effects apart within flight_tolerance, and on the simulated
  // flights a false coupling that happens to fly 1 % better takes the step from a vibration line the live estimator
  // does not run (diagnose_search_test's Vibration cases).
  bool choose_by_flight = false;
  // What "flies worse" means under those rules: a validation velocity RMSE higher by more than this share, or a
  // likelihood lower by more than this share of its size. Within it two models fly alike (the same 50-100 s of
  // validation cannot tell them apart), so an effect that leaves the velocity as it was (a vibration line, a first
  // step that only makes the velocity self-consistent) is not refused for it, and the residual chooses between them.
  double flight_tolerance = 0.01;
  std::string session;  // how the report names the data
  // The validation window holds other flights than the training window (a flight set's validating flights): their
  // velocity is scored as the model flies on a new flight, its offset unknown (estimator::score_velocity).
  bool validation_on_other_flights = false;
  // A candidate whose fitted values exceed these is refused, whatever its gain.
  estimator::PlausibilityLimits limits;
  // Called as the search moves, from the fitting threads (so it must be thread-safe); may be empty.
  std::function<void(const DiagnoseProgress&)> progress;
};

// "reference", "imu", "filter": the spellings of diagnose's --velocity (identify spells eq. (12)'s velocity "eq12").
std::string_view diagnose_spelling(VelocitySource velocity);

// A multirotor's manoeuvres (attitude changes and the velocity they drive) stay below this; the measurement noise of
// the filter error method is what lies above it (docs/identification.md).
inline constexpr double kManoeuvreBandHz = 5.0;
// The filter that gives the velocity from the IMU alone (velocity `filter`): the defaults, with the
// measurement noise set from the data: the RMS of its block means' levelled horizontal specific force above
// kManoeuvreBandHz over the training window, when larger than the default.
estimator::DragVelocityConfig filter_config(const Signals& signals, const DiagnoseOptions& options);

// Makes `setup` take its velocity from the filter (velocity `filter`): its noises (filter_config), its blocks
// (identification_block), and the band the model is compared in: the blocks' Nyquist frequency, or the requested
// --lowpass when lower. Above it the filter sees nothing, and the vibration there would only bury the innovations
// the fit is about. Returns that band limit, Hz.
double use_filter(ModelSetup& setup, const Signals& signals, const DiagnoseOptions& options);

// Throws std::invalid_argument for an invalid series, bad options (no axis, a window without data, a reference
// velocity without a reference) or too few samples in a window (the residual analysis needs 64).
Diagnosis run_diagnosis(const estimator::ImuSeries& series, const DiagnoseOptions& options);

// The significance rule's test (docs/effects.md): an F-test on the validation window's residual sums of squares,
//   F = ((rss_before - rss_after) / q) / (rss_after / (n_eff - p)),
// q the parameters the candidate adds (at least 1), p all of the candidate model's, n_eff the validation residuals'
// effective count (effective_samples). p_value from the F(q, n_eff - p) distribution; 1 when rss_after >= rss_before.
struct FTest {
  double statistic = 0.0;
  double p_value = 1.0;
};
FTest validation_f_test(double rss_before, double rss_after, std::size_t added, std::size_t parameters, double n_eff);

// The velocity's test (docs/effects.md): whether a model flies nearer the reference than zero velocity beyond what
// chance gives, from its gain over zero velocity on the validation window, block by block
// (estimator::VelocityEvaluation::gain_over_zero). A one-sided t-test of the blocks' mean (Diebold and Mariano's test
// of two forecasts' losses), their count corrected for their own correlation (effective_samples over lags up to half
// of them), since a velocity error lasts as long as the drag's time constant and more. p_value 1 when the mean gain
// is not positive or fewer than two blocks are worth anything.
FTest velocity_gain_test(std::span<const double> block_gains);

// A parameter within this fraction of a bound's size (on it, for a bound of zero) is "at the bound": the data pushed it
// to the edge, so its value says more about the range than about the vehicle.
inline constexpr double kAtBoundFraction = 0.01;
inline constexpr double kOnZeroBound = 1e-9;
// One readable line per parameter at a bound, "<owner> <name> = <value> <unit> is at its lower bound 0: ...";
// owners[i] names parameter i's effect (or "base").
std::vector<std::string> parameters_at_bounds(std::span<const Parameter> params, std::span<const double> values,
                                              std::span<const std::string> owners);

// n / (1 + 2 sum_k rho_k): the number of independent samples a correlated series is worth (Bartlett), with the sum
// over the initial run of positive autocorrelations up to max_lag. Between 1 and n.
double effective_samples(std::span<const double> x, std::size_t max_lag);

}  // namespace imubridge::diagnose
