#pragma once
// What structure is left in a model's residual (docs/residual-analysis.md): its level, whether it is white, the lines
// in its spectrum, which candidate signal it follows and at what lag, and whether it drifts. analyse_residual() fills
// a ResidualAnalysis (diagnosis.hpp); the smaller functions are its parts, public for reuse and tests.
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "diagnose/diagnosis.hpp"

namespace imubridge::diagnose {

// A signal the residual may follow ("gyro.y", "velocity.x", ...), sampled at the residual's times.
struct NamedSignal {
  std::string name;
  std::vector<double> values;  // same length as the residual
};

struct AnalysisOptions {
  double max_lag_s = 0.5;      // cross-correlation lags searched: [-max_lag_s, +max_lag_s]
  int acf_lags = 0;            // autocorrelation lags kept in the result; 0: as many as max_lag_s spans
  double significance = 0.01;  // level of the whiteness, correlation (family-wise) tests
  std::vector<std::pair<double, double>> ignore_bands;  // Hz; peaks inside are marked ignored, not unexplained
  // Whiteness lags are multiples of this, raised to kWhitenessLagSpacingS. The caller knows its own filters: a
  // model whose regressors are smoothed over a window correlates its residual across that window.
  double whiteness_lag_spacing_s = 0.0;
};

// Whiteness is tested at lags spaced by this much (docs/residual-analysis.md): the differentiator and the sensors'
// filters correlate neighbouring samples over a few milliseconds, which is not structure the model could explain.
// 5 x 5 ms: a first-order filter of up to 5 ms leaves a correlation of e^-5 = 0.007 at this lag.
inline constexpr double kWhitenessLagSpacingS = 0.025;
inline constexpr int kMaxWhitenessLags = 20;
// A spectral line stands at least this far above the local median of the spectrum.
inline constexpr double kPeakPowerRatio = 10.0;
// A significant trend must also explain at least this fraction of the residual's variance.
inline constexpr double kMaterialTrendFraction = 0.01;

// Throws std::invalid_argument for fewer than 64 samples, mismatched lengths, non-finite values, a time that does not
// increase, or options out of range.
ResidualAnalysis analyse_residual(std::span<const double> t, std::span<const double> residual,
                                  std::span<const NamedSignal> candidates, const AnalysisOptions& options);

// The structure a residual analysis found, as report entries for one axis: every line not ignored, every
// significant correlation, a significant trend; and when the residual is not white yet none of those (nor an ignored
// line) accounts for it, one "autocorrelation" entry pointing at its strongest lag.
std::vector<Unexplained> unexplained_structure(const ResidualAnalysis& analysis, std::string axis);

// ---- parts ----

struct Trend {
  double slope = 0.0, std_error = 0.0;  // per second
  double variance_fraction = 0.0;       // share of x's variance the line accounts for
  bool significant = false;             // |slope| > 3 std errors and variance_fraction >= kMaterialTrendFraction
};
// Least-squares line through x(t); its slope's standard error is widened by Bartlett's factor between the detrended
// series' autocorrelation and the time ramp's, up to max_lag (the same effective-sample-size rule as the
// correlations). Zero and not significant for a constant x or t.
Trend fit_trend(std::span<const double> t, std::span<const double> x, std::size_t max_lag);

// 1 / median(dt). Throws std::invalid_argument when the median step is not positive and finite.
double sample_rate_hz(std::span<const double> t);

// Normalised sample autocorrelation (acf[0] = 1, the usual biased estimator with the mean removed) at lags
// 0..max_lag. All zeros after acf[0] for a constant series.
std::vector<double> autocorrelation(std::span<const double> x, std::size_t max_lag);

struct LjungBox {
  int lags = 0;
  double q = 0.0;
  double p = 1.0;
};
// Ljung-Box on the autocorrelation at lags spacing, 2*spacing, ..., lags*spacing:
//   Q = n(n+2)/v * sum_k rho(k*spacing)^2 / (n - k*spacing),  v = 1 + 2 sum_{j=1}^{spacing-1} rho(j)^2,
// chi-square with `lags` degrees of freedom. spacing = 1 is the classical test; a larger spacing tolerates
// correlation shorter than `spacing` samples (v is Bartlett's variance of those lags' estimates).
LjungBox ljung_box(std::span<const double> x, int lags, int spacing = 1);

struct Spectrum {
  std::vector<double> frequency_hz;
  std::vector<double> psd;  // one-sided, (unit)^2/Hz
};
// Welch's estimate: Hann window, 50 % overlap, each segment's mean removed, segment length the power of two giving a
// resolution in (0.25, 0.5] Hz, shortened to at most a quarter of the data (at least 16 samples).
Spectrum welch_psd(std::span<const double> x, double sample_rate_hz);

// Lines: bins (not the lowest two) that are the largest within +-4 bins and at least kPeakPowerRatio times the
// median of the 65 bins around them; frequency refined by a parabola through the log PSD. Strongest first.
std::vector<SpectralPeak> find_peaks(const Spectrum& spectrum,
                                     std::span<const std::pair<double, double>> ignore_bands = {});

// The lag in [-max_lag, +max_lag] samples at which residual(t) and signal(t - lag) correlate most strongly (Pearson
// with whole-series means and deviations). `threshold` is the |r| above which that is significant at
// `significance` after a Bonferroni correction over `comparisons` tests (pass lags x signals), with the effective
// sample size n / (1 + 2 sum_k rho_residual(k) rho_signal(k)) over k = 1..max_lag (Bartlett). A constant signal
// correlates with nothing (coefficient 0, not significant).
SignalCorrelation best_lagged_correlation(std::span<const double> residual, const NamedSignal& signal,
                                          double sample_rate_hz, std::size_t max_lag, double significance,
                                          std::size_t comparisons);

}  // namespace imubridge::diagnose
