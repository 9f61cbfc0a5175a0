#pragma once
// What `imubridge diagnose` finds (docs/effects.md, docs/residual-analysis.md): the base model's fit, each effect the
// greedy search added, the residual's analysis before and after, and what structure is left unexplained. Filled by
// diagnose::run_diagnosis(); written by write_report_json() and write_report_html(). Plain data, no behaviour.
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "diagnose/gyro_against_reference.hpp"
#include "estimator/params.hpp"
#include "identification/velocity_scores.hpp"

namespace imubridge::diagnose {

// ---- residual analysis (residual_analysis.hpp computes it) ----

// A candidate signal's best cross-correlation with the residual over the lags searched.
struct SignalCorrelation {
  std::string signal;        // e.g. "gyro.y", "gyro_rate.y", "gyro.y^2", "accel.z", "velocity.x", "tilt.x", "thrust"
  double lag_s = 0.0;        // residual(t) best matches signal(t - lag_s); positive: the residual lags the signal
  double coefficient = 0.0;  // Pearson correlation at that lag, -1..1
  double threshold = 0.0;    // |coefficient| above this is significant (accounts for the residual's own correlation)
  bool significant = false;
};

struct SpectralPeak {
  double frequency_hz = 0.0;
  double power_ratio = 0.0;  // the peak's power spectral density over the local median (a line stands far above)
  bool ignored = false;      // inside a band the caller told the search to ignore (AnalysisOptions::ignore_bands)
};

struct ResidualAnalysis {
  std::size_t samples = 0;
  double sample_rate_hz = 0.0;  // 1 / median sample step
  double rms = 0.0;             // m/s^2
  double mean = 0.0;            // m/s^2
  // Normalised autocorrelation at lags 0..max_lag samples (acf[0] = 1).
  std::vector<double> autocorrelation;
  // Ljung-Box portmanteau test on the autocorrelation of the (decimated, see docs) residual.
  int ljung_box_lags = 0;
  double ljung_box_lag_spacing_s = 0.0;  // the test's lags are multiples of this (docs/residual-analysis.md)
  double ljung_box_q = 0.0;
  double ljung_box_p = 1.0;
  bool white = true;  // p >= the test's significance level
  // Welch power spectral density, one-sided, (m/s^2)^2/Hz.
  std::vector<double> frequency_hz;
  std::vector<double> psd;
  std::vector<SpectralPeak> peaks;              // strongest first
  std::vector<SignalCorrelation> correlations;  // strongest |coefficient| first
  // Linear trend of the residual over time: slope, its standard error, significant when |slope| > 3 std errors.
  double trend_per_s = 0.0;
  double trend_std_error = 0.0;
  bool trend_significant = false;
  double trend_variance_fraction = 0.0;  // share of the residual's variance the trend accounts for
};

// ---- the model search ----

struct ParameterEstimate {
  std::string name;  // "k_x", "bias.y", "tau", ...; unique within an effect
  double value = 0.0;
  double std_error = 0.0;  // NaN when the covariance could not be computed
  std::string unit;        // "1/s", "m/s^2", "s", ...
};

// One fitted model: the base model plus zero or more effects, fitted together on the training window.
struct ModelFit {
  std::vector<std::string> effects;            // names as in docs/effects.md, in the order added (empty: base model)
  std::vector<ParameterEstimate> base_params;  // the base model's parameters, refitted with the effects
  std::vector<std::vector<ParameterEstimate>> effect_params;  // one list per entry of `effects`
  std::size_t free_parameters = 0;
  double rmse_train = 0.0;          // m/s^2, over the axes diagnosed
  double rmse_validation = 0.0;     // m/s^2
  std::vector<double> convergence;  // cost (sqrt of the sum of squared residuals) after each solver iteration
  std::string std_error_failure;    // why the standard errors (NaN then) could not be computed; empty when they were
  // Parameters at or within 1 % of a bound of their search range: the data pushed them there, so their value says
  // more about the range than about the vehicle. One readable line each.
  std::vector<std::string> at_bounds;
  // Values beyond the plausibility table (identification/plausibility.hpp), one line each (a candidate with any is
  // refused; the base model is reported with them).
  std::vector<std::string> implausible;
  std::optional<estimator::VelocityScores> velocity;  // the estimator run with this model; with a reference only
  // The filter's log-likelihood of the accelerometer with this model (estimator::filter_log_likelihood); from the IMU
  // alone (velocity `filter` or `imu`), where it is what a step is judged by.
  std::optional<estimator::FilterLikelihood> likelihood;
};

// One candidate tried at one step of the greedy search.
struct CandidateTrial {
  std::string effect;
  double rmse_train = 0.0;
  double rmse_validation = 0.0;
  double statistic = 0.0;  // the significance rule's statistic (docs/effects.md, "The significance rule")
  double p_value = 1.0;
  bool significant = false;
  // What the candidate does for what users fly with (docs/effects.md, "The rules"): with the reference as the
  // velocity, the estimator's validation velocity RMSE (m/s); from the IMU alone, the filter's validation
  // log-likelihood per measurement (nats). A step must not make it worse (DiagnoseOptions::flight_tolerance).
  std::optional<double> velocity_validation{};
  std::optional<double> likelihood_validation{};
  // With the reference, a first drag (the current model gives no velocity): the one-sided p-value of its validation
  // velocity against zero velocity's (velocity_gain_test), which adds it where the airframe's vibration hides the drag
  // from the specific-force residual (docs/effects.md, "The velocity's test"). nullopt where not run.
  std::optional<double> velocity_test_p{};
  // With the reference, gyro_bias: the p-value of the gyro's bias against the reference's attitude on the validation
  // window (gyro_against_reference), which adds it though the specific force hardly shows it (docs/effects.md, "The
  // reference attitude's test"). nullopt where not run.
  std::optional<double> attitude_test_p{};
  // Non-empty for a candidate that passes by the velocity's or the attitude's test alone (the residual's rules do not
  // pass it): says so.
  std::string admitted_by{};
  // Why a tried candidate was not added, naming the rule: the F-test (its p-value against the level), the
  // minimum-gain rule (its gain against the minimum), or the velocity or likelihood rule. Empty for the one added.
  std::string rejected_by;
  std::string skipped;  // non-empty: why this effect was not tried (does not apply to this data, failed to fit,
                        // physically implausible)
  std::vector<std::string> with{};  // effects it needs (Effect::needs), fitted and added together with it
  // Its fit was past the plausibility table on an axis that, held at zero, clears it (search.cpp,
  // axes_to_hold): those parameters (ModelSetup::held_at_zero's names) and a line saying so. Empty otherwise.
  std::vector<std::string> held_at_zero{};
  std::string held{};
};

struct Step {
  std::string effect;                     // the effect added at this step
  std::vector<ParameterEstimate> params;  // its parameters, after the refit of everything
  ModelFit fit;                           // the whole model after this step
  double rmse_train_before = 0.0, rmse_validation_before = 0.0;
  std::vector<CandidateTrial> candidates;  // every candidate tried at this step, best validation RMSE first
  std::vector<ResidualAnalysis> residual;  // validation residual after this step, one per axis diagnosed
  std::vector<std::string> with{};         // the effects it needed, added with it before it
  // The axes a candidate held at zero (CandidateTrial::held), fitted again free once this step's effect was in and
  // kept so (search.cpp, release_holds): which, and their values. Empty otherwise.
  std::string released{};
};

// Structure left in the final residual that no library effect took away.
struct Unexplained {
  // "frequency", "correlation", "trend", "autocorrelation", or "velocity ramp" (from the IMU alone: the filter's own
  // velocity ramps past what a multirotor cruises at)
  std::string kind;
  std::string axis;   // "x" or "y"
  std::string where;  // one readable line: "line at 37.5 Hz, 40x the median power", "accel.z at lag +0.010 s, r=0.41"
  double frequency_hz = 0.0;  // kind == "frequency"
  std::string signal;         // kind == "correlation"
  double lag_s = 0.0;         // kind == "correlation"
  double value = 0.0;  // power ratio, correlation coefficient, trend (m/s^2 per s), or the velocity's ramp (m/s^2)
};

// From the IMU alone: the line through the final model's filter velocity across both windows, per axis (search.cpp,
// name_velocity_ramps). Named in `unexplained` when significant and ramping past a cruising speed.
struct VelocityRamp {
  std::string axis;                     // "x" or "y"
  double span_s = 0.0;                  // both windows' span
  double per_s = 0.0, std_error = 0.0;  // its slope, m/s^2, and the slope's standard error (Bartlett-widened)
  bool named = false;
  double ramp_m_s() const { return per_s * span_s; }  // the line's change over the span
};

// From the IMU alone, with a reference that only scores: the least-squares scale (through zero) of the filter's
// one-step velocity, the one the fit regressed the drag on, against the reference's, over the training window (the
// air velocity against the ground's: alike without wind). Below 1 the prediction is shrunk, and a drag fitted on it
// comes out larger to make up for it (docs/identification.md, "What is left, measured").
struct PredictionScale {
  std::string axis;  // "x" or "y"
  double scale = 0.0;
};

// Per axis, the validation window's signals for the plots.
struct AxisSeries {
  std::string axis;                                       // "x" or "y"
  std::vector<double> t;                                  // s, session time
  std::vector<double> measured, base_model, final_model;  // m/s^2
};

struct Diagnosis {
  // What was asked.
  std::string session;            // "DB#ID" or a description of the data
  std::string model;              // "paper" or "full"
  std::vector<std::string> axes;  // "x", "y"
  std::string velocity_source;    // "reference" or "imu" (eq. 12 / dead reckoning from the gyro-integrated tilt)
  double train_start = 0.0, train_end = 0.0, validate_start = 0.0, validate_end = 0.0;  // s
  std::string significance_rule;  // one line: the rule and its level
  // What was found.
  ModelFit base;
  std::vector<ResidualAnalysis> base_residual;  // validation residual of the base model, one per axis
  std::vector<Step> steps;                      // in the order chosen
  std::vector<CandidateTrial> last_candidates;  // the step that stopped the search: every candidate and why it failed
  ModelFit final;
  std::vector<ResidualAnalysis> final_residual;
  bool residual_white = false;  // every axis's final validation residual passes Ljung-Box
  std::vector<Unexplained> unexplained;
  std::vector<VelocityRamp> velocity_ramps;  // from the IMU alone, when the filter runs; empty otherwise
  std::vector<PredictionScale> prediction_scale;  // from the IMU alone with a reference; empty otherwise
  std::vector<AxisSeries> series;
  // Zero velocity's error (m/s): the floor any velocity estimate must beat. With a reference only.
  std::optional<estimator::VelocityScores> zero_velocity;
  // With the reference's attitude: the gyro's bias against it on the training and validation windows.
  std::optional<GyroAgainstReference> gyro_train, gyro_validation;
  // The final model as the live estimator runs it (PARAMS.json).
  estimator::ModelParams final_params;
  std::vector<std::string> warnings;  // e.g. the IMU axes disagreeing with the data; shown first
  std::string imu_axes;               // how the samples were turned into body axes (declared or detected)
};

}  // namespace imubridge::diagnose
