#include "diagnose/residual_analysis.hpp"

#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/normal.hpp>
#include <cmath>
#include <complex>
#include <cstdio>
#include <numbers>
#include <numeric>
#include <stdexcept>
#include <unsupported/Eigen/FFT>

namespace imubridge::diagnose {
namespace {

constexpr std::size_t kMinSamples = 64;
constexpr std::size_t kMinSegment = 16;
constexpr int kPeakExclusionBins = 4;      // twice the Hann main lobe's half-width: a line's side lobes are not lines
constexpr int kMedianHalfWindowBins = 32;  // the local floor a line is measured against
constexpr double kMaxResolutionHz = 0.5;

using Complex = std::complex<double>;

std::size_t next_power_of_two(std::size_t n) {
  std::size_t p = 1;
  while (p < n) p <<= 1;
  return p;
}

std::size_t previous_power_of_two(std::size_t n) {
  std::size_t p = 1;
  while (p * 2 <= n) p <<= 1;
  return p;
}

double mean_of(std::span<const double> x) { return std::accumulate(x.begin(), x.end(), 0.0) / double(x.size()); }

// Half spectrum of x minus its mean, zero-padded to nfft (a power of two, so circular products do not wrap when
// nfft >= n + the largest lag wanted).
std::vector<Complex> centred_spectrum(std::span<const double> x, std::size_t nfft) {
  const double mean = mean_of(x);
  std::vector<double> padded(nfft, 0.0);
  for (std::size_t i = 0; i < x.size(); ++i) padded[i] = x[i] - mean;
  Eigen::FFT<double> fft;
  fft.SetFlag(Eigen::FFT<double>::HalfSpectrum);
  std::vector<Complex> spectrum;
  fft.fwd(spectrum, padded);
  return spectrum;
}

// c[l] = sum_i x_i y_{i-l} for l = 0..nfft-1 (negative lags wrap to the end), from the two half spectra.
std::vector<double> circular_cross_products(const std::vector<Complex>& x, const std::vector<Complex>& y) {
  std::vector<Complex> product(x.size());
  for (std::size_t k = 0; k < x.size(); ++k) product[k] = x[k] * std::conj(y[k]);
  Eigen::FFT<double> fft;
  fft.SetFlag(Eigen::FFT<double>::HalfSpectrum);
  std::vector<double> out;
  fft.inv(out, product);
  return out;
}

std::vector<double> acf_from_spectrum(const std::vector<Complex>& spectrum, std::size_t n, std::size_t max_lag) {
  const std::vector<double> c = circular_cross_products(spectrum, spectrum);
  std::vector<double> acf(max_lag + 1, 0.0);
  acf[0] = 1.0;
  if (c[0] <= 0.0) return acf;  // constant series
  for (std::size_t k = 1; k <= max_lag && k < n; ++k) acf[k] = c[k] / c[0];
  return acf;
}

// Bartlett: the variance of a correlation estimate between two series, relative to white ones, is
// sum_k rho_x(k) rho_y(k) over all k. Never below 1: a test must not become bolder than for white series.
double bartlett_factor(std::span<const double> acf_x, std::span<const double> acf_y, std::size_t max_lag) {
  double sum = 0.0;
  for (std::size_t k = 1; k <= max_lag && k < acf_x.size() && k < acf_y.size(); ++k) sum += acf_x[k] * acf_y[k];
  return std::max(1.0, 1.0 + 2.0 * sum);
}

// The residual's spectrum and autocorrelation, computed once and shared by every candidate's correlation.
struct PreparedResidual {
  std::size_t n = 0;
  std::size_t nfft = 0;
  double deviation = 0.0;  // population standard deviation
  std::vector<Complex> spectrum;
  std::vector<double> acf;

  PreparedResidual(std::span<const double> x, std::size_t max_lag)
      : n(x.size()), nfft(next_power_of_two(x.size() + max_lag + 1)), spectrum(centred_spectrum(x, nfft)) {
    acf = acf_from_spectrum(spectrum, n, max_lag);
    const double mean = mean_of(x);
    double ss = 0.0;
    for (double v : x) ss += (v - mean) * (v - mean);
    deviation = std::sqrt(ss / double(n));
  }
};

SignalCorrelation correlate(const PreparedResidual& residual, const NamedSignal& signal, double sample_rate,
                            std::size_t max_lag, double significance, std::size_t comparisons) {
  SignalCorrelation out;
  out.signal = signal.name;
  out.threshold = 1.0;
  const std::vector<double>& y = signal.values;
  const double mean = mean_of(y);
  double ss = 0.0;
  for (double v : y) ss += (v - mean) * (v - mean);
  const double deviation = std::sqrt(ss / double(y.size()));
  if (deviation == 0.0 || residual.deviation == 0.0) return out;

  const std::vector<Complex> y_spectrum = centred_spectrum(y, residual.nfft);
  const std::vector<double> cross = circular_cross_products(residual.spectrum, y_spectrum);
  const std::vector<double> y_acf = acf_from_spectrum(y_spectrum, y.size(), max_lag);

  const auto n = static_cast<long>(residual.n);
  const auto lag_limit = static_cast<long>(std::min<std::size_t>(max_lag, residual.n - 1));
  double best = 0.0;
  long best_lag = 0;
  for (long lag = -lag_limit; lag <= lag_limit; ++lag) {
    const std::size_t index = lag >= 0 ? std::size_t(lag) : residual.nfft - std::size_t(-lag);
    const double r =
        std::clamp(cross[index] / (double(n - std::labs(lag)) * residual.deviation * deviation), -1.0, 1.0);
    if (std::abs(r) > std::abs(best)) {
      best = r;
      best_lag = lag;
    }
  }
  const double n_eff = double(residual.n) / bartlett_factor(residual.acf, y_acf, max_lag);
  const double alpha = significance / double(std::max<std::size_t>(1, comparisons));
  const double z =
      boost::math::quantile(boost::math::complement(boost::math::normal_distribution<double>(), alpha / 2));
  out.lag_s = double(best_lag) / sample_rate;
  out.coefficient = best;
  out.threshold = std::min(1.0, z / std::sqrt(n_eff));
  out.significant = std::abs(best) > out.threshold;
  return out;
}

void require_finite(std::span<const double> x, const std::string& what) {
  if (!std::all_of(x.begin(), x.end(), [](double v) { return std::isfinite(v); }))
    throw std::invalid_argument("residual analysis: " + what + " has a value that is not finite");
}

void validate(std::span<const double> t, std::span<const double> residual, std::span<const NamedSignal> candidates,
              const AnalysisOptions& options) {
  if (t.size() != residual.size()) throw std::invalid_argument("residual analysis: time and residual lengths differ");
  if (residual.size() < kMinSamples)
    throw std::invalid_argument("residual analysis: needs at least " + std::to_string(kMinSamples) + " samples, got " +
                                std::to_string(residual.size()));
  require_finite(t, "time");
  require_finite(residual, "the residual");
  for (const NamedSignal& c : candidates) {
    if (c.values.size() != residual.size())
      throw std::invalid_argument("residual analysis: candidate signal '" + c.name +
                                  "' is not as long as the residual");
    require_finite(c.values, "candidate signal '" + c.name + "'");
  }
  if (!(options.max_lag_s >= 0.0) || !std::isfinite(options.max_lag_s))
    throw std::invalid_argument("residual analysis: max_lag_s must be finite and >= 0");
  if (options.acf_lags < 0) throw std::invalid_argument("residual analysis: acf_lags must be >= 0");
  if (!(options.significance > 0.0 && options.significance < 1.0))
    throw std::invalid_argument("residual analysis: significance must be in (0, 1)");
  for (const auto& [lo, hi] : options.ignore_bands)
    if (!(lo <= hi)) throw std::invalid_argument("residual analysis: an ignored band must be F0:F1 with F0 <= F1");
}

}  // namespace

Trend fit_trend(std::span<const double> t, std::span<const double> x, std::size_t max_lag) {
  const std::size_t n = x.size();
  const double t_mean = mean_of(t), x_mean = mean_of(x);
  double sxx = 0.0, sxy = 0.0, syy = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    sxx += (t[i] - t_mean) * (t[i] - t_mean);
    sxy += (t[i] - t_mean) * (x[i] - x_mean);
    syy += (x[i] - x_mean) * (x[i] - x_mean);
  }
  Trend out;
  if (sxx <= 0.0 || syy <= 0.0) return out;
  out.slope = sxy / sxx;
  std::vector<double> detrended(n);
  double sse = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    detrended[i] = x[i] - x_mean - out.slope * (t[i] - t_mean);
    sse += detrended[i] * detrended[i];
  }
  const double factor = bartlett_factor(autocorrelation(detrended, max_lag), autocorrelation(t, max_lag), max_lag);
  out.std_error = std::sqrt(sse / double(n - 2) / sxx * factor);
  out.variance_fraction = out.slope * out.slope * sxx / syy;
  out.significant = std::abs(out.slope) > 3.0 * out.std_error && out.variance_fraction >= kMaterialTrendFraction;
  return out;
}

namespace {

std::string printf_string(const char* format, auto... args) {
  char buffer[256];
  std::snprintf(buffer, sizeof buffer, format, args...);
  return buffer;
}

}  // namespace

double sample_rate_hz(std::span<const double> t) {
  if (t.size() < 2) throw std::invalid_argument("residual analysis: a sample rate needs at least two times");
  std::vector<double> dt(t.size() - 1);
  for (std::size_t i = 0; i + 1 < t.size(); ++i) dt[i] = t[i + 1] - t[i];
  auto middle = dt.begin() + std::ptrdiff_t(dt.size() / 2);
  std::nth_element(dt.begin(), middle, dt.end());
  const double median = *middle;
  if (!(median > 0.0) || !std::isfinite(median))
    throw std::invalid_argument("residual analysis: time must increase (median sample step is not positive)");
  return 1.0 / median;
}

std::vector<double> autocorrelation(std::span<const double> x, std::size_t max_lag) {
  if (x.empty()) throw std::invalid_argument("autocorrelation: empty series");
  return acf_from_spectrum(centred_spectrum(x, next_power_of_two(x.size() + max_lag + 1)), x.size(), max_lag);
}

LjungBox ljung_box(std::span<const double> x, int lags, int spacing) {
  if (lags < 1 || spacing < 1) throw std::invalid_argument("ljung_box: lags and spacing must be >= 1");
  const std::size_t n = x.size();
  const std::size_t last_lag = std::size_t(lags) * std::size_t(spacing);
  if (last_lag >= n) throw std::invalid_argument("ljung_box: lags * spacing must be shorter than the series");
  const std::vector<double> acf = autocorrelation(x, last_lag);
  double v = 1.0;
  for (int j = 1; j < spacing; ++j) v += 2.0 * acf[std::size_t(j)] * acf[std::size_t(j)];
  double sum = 0.0;
  for (int k = 1; k <= lags; ++k) {
    const std::size_t lag = std::size_t(k) * std::size_t(spacing);
    sum += acf[lag] * acf[lag] / double(n - lag);
  }
  LjungBox out;
  out.lags = lags;
  out.q = double(n) * double(n + 2) / v * sum;
  out.p = boost::math::cdf(boost::math::complement(boost::math::chi_squared_distribution<double>(lags), out.q));
  return out;
}

Spectrum welch_psd(std::span<const double> x, double sample_rate) {
  if (x.size() < kMinSegment)
    throw std::invalid_argument("welch_psd: needs at least " + std::to_string(kMinSegment) + " samples");
  if (!(sample_rate > 0.0) || !std::isfinite(sample_rate))
    throw std::invalid_argument("welch_psd: the sample rate must be positive");
  const std::size_t wanted = next_power_of_two(std::size_t(std::ceil(sample_rate / kMaxResolutionHz)));
  const std::size_t segment = std::max(kMinSegment, std::min(wanted, previous_power_of_two(x.size() / 4)));
  const std::size_t step = segment / 2;
  const std::size_t segments = (x.size() - segment) / step + 1;

  std::vector<double> window(segment);
  double window_power = 0.0;
  for (std::size_t i = 0; i < segment; ++i) {
    window[i] = 0.5 * (1.0 - std::cos(2.0 * std::numbers::pi * double(i) / double(segment)));  // periodic Hann
    window_power += window[i] * window[i];
  }
  Eigen::FFT<double> fft;
  fft.SetFlag(Eigen::FFT<double>::HalfSpectrum);
  const std::size_t bins = segment / 2 + 1;
  std::vector<double> psd(bins, 0.0);
  std::vector<double> frame(segment);
  std::vector<Complex> spectrum;
  for (std::size_t s = 0; s < segments; ++s) {
    const std::span<const double> part = x.subspan(s * step, segment);
    const double mean = mean_of(part);
    for (std::size_t i = 0; i < segment; ++i) frame[i] = (part[i] - mean) * window[i];
    fft.fwd(spectrum, frame);
    for (std::size_t k = 0; k < bins; ++k) psd[k] += std::norm(spectrum[k]);
  }
  Spectrum out;
  out.frequency_hz.resize(bins);
  out.psd.resize(bins);
  const double scale = 1.0 / (sample_rate * window_power * double(segments));
  for (std::size_t k = 0; k < bins; ++k) {
    const bool edge = k == 0 || k == bins - 1;  // DC and Nyquist have no mirror image to fold in
    out.psd[k] = psd[k] * scale * (edge ? 1.0 : 2.0);
    out.frequency_hz[k] = double(k) * sample_rate / double(segment);
  }
  return out;
}

std::vector<SpectralPeak> find_peaks(const Spectrum& spectrum,
                                     std::span<const std::pair<double, double>> ignore_bands) {
  const std::vector<double>& p = spectrum.psd;
  const int bins = int(p.size());
  std::vector<SpectralPeak> peaks;
  if (bins < 4 || spectrum.frequency_hz.size() != p.size()) return peaks;
  const double bin_width = spectrum.frequency_hz[1] - spectrum.frequency_hz[0];
  std::vector<double> local;
  // Bin 0 is emptied by the per-segment mean removal and bin 1 is then the spectrum's edge, where slow drift would
  // pass for a line: the trend and whiteness tests cover those frequencies.
  for (int k = 2; k + 1 < bins; ++k) {
    bool largest = true;
    for (int j = std::max(0, k - kPeakExclusionBins); j <= std::min(bins - 1, k + kPeakExclusionBins) && largest; ++j)
      largest = j == k || (j < k ? p[j] < p[k] : p[j] <= p[k]);
    if (!largest) continue;
    const int width = 2 * kMedianHalfWindowBins + 1;
    const int lo = std::clamp(k - kMedianHalfWindowBins, 1, std::max(1, bins - width));
    const int hi = std::min(bins, lo + width);
    local.assign(p.begin() + lo, p.begin() + hi);
    auto middle = local.begin() + std::ptrdiff_t(local.size() / 2);
    std::nth_element(local.begin(), middle, local.end());
    if (*middle <= 0.0 || p[k] < kPeakPowerRatio * *middle) continue;

    double offset = 0.0;  // parabola through the log PSD: a Hann line's shape is close to Gaussian near its top
    if (p[k - 1] > 0.0 && p[k + 1] > 0.0) {
      const double a = std::log(p[k - 1]), b = std::log(p[k]), c = std::log(p[k + 1]);
      const double curvature = a - 2.0 * b + c;
      if (curvature < 0.0) offset = std::clamp(0.5 * (a - c) / curvature, -0.5, 0.5);
    }
    SpectralPeak peak;
    peak.frequency_hz = spectrum.frequency_hz[std::size_t(k)] + offset * bin_width;
    peak.power_ratio = p[k] / *middle;
    peak.ignored = std::any_of(ignore_bands.begin(), ignore_bands.end(), [&](const auto& band) {
      return peak.frequency_hz >= band.first && peak.frequency_hz <= band.second;
    });
    peaks.push_back(peak);
  }
  std::stable_sort(peaks.begin(), peaks.end(),
                   [](const SpectralPeak& a, const SpectralPeak& b) { return a.power_ratio > b.power_ratio; });
  return peaks;
}

SignalCorrelation best_lagged_correlation(std::span<const double> residual, const NamedSignal& signal,
                                          double sample_rate, std::size_t max_lag, double significance,
                                          std::size_t comparisons) {
  if (signal.values.size() != residual.size() || residual.size() < 2)
    throw std::invalid_argument("best_lagged_correlation: the signal '" + signal.name +
                                "' must be as long as the residual (>= 2 samples)");
  return correlate(PreparedResidual(residual, max_lag), signal, sample_rate, max_lag, significance, comparisons);
}

ResidualAnalysis analyse_residual(std::span<const double> t, std::span<const double> residual,
                                  std::span<const NamedSignal> candidates, const AnalysisOptions& options) {
  validate(t, residual, candidates, options);
  ResidualAnalysis out;
  const std::size_t n = residual.size();
  const double rate = sample_rate_hz(t);
  out.samples = n;
  out.sample_rate_hz = rate;
  out.mean = mean_of(residual);
  double squares = 0.0;
  for (double v : residual) squares += v * v;
  out.rms = std::sqrt(squares / double(n));

  // Lags searched for correlations, and the truncation of every Bartlett sum: max_lag_s, at most a quarter of the data.
  const std::size_t max_lag = std::min<std::size_t>(std::size_t(std::llround(options.max_lag_s * rate)), n / 4);
  const std::size_t acf_lags = options.acf_lags > 0 ? std::min<std::size_t>(std::size_t(options.acf_lags), n - 1)
                                                    : std::max<std::size_t>(max_lag, 1);
  out.autocorrelation = autocorrelation(residual, acf_lags);

  const int spacing =
      std::max(1, int(std::lround(std::max(kWhitenessLagSpacingS, options.whiteness_lag_spacing_s) * rate)));
  const int lags = std::clamp(int(n / std::size_t(spacing)) / 5, 1, kMaxWhitenessLags);
  const LjungBox whiteness = ljung_box(residual, lags, spacing);
  out.ljung_box_lags = whiteness.lags;
  out.ljung_box_lag_spacing_s = double(spacing) / rate;
  out.ljung_box_q = whiteness.q;
  out.ljung_box_p = whiteness.p;
  out.white = whiteness.p >= options.significance;

  Spectrum spectrum = welch_psd(residual, rate);
  out.peaks = find_peaks(spectrum, options.ignore_bands);
  out.frequency_hz = std::move(spectrum.frequency_hz);
  out.psd = std::move(spectrum.psd);

  const PreparedResidual prepared(residual, max_lag);
  const std::size_t comparisons = (2 * max_lag + 1) * std::max<std::size_t>(1, candidates.size());
  for (const NamedSignal& candidate : candidates)
    out.correlations.push_back(correlate(prepared, candidate, rate, max_lag, options.significance, comparisons));
  std::stable_sort(out.correlations.begin(), out.correlations.end(),
                   [](const auto& a, const auto& b) { return std::abs(a.coefficient) > std::abs(b.coefficient); });

  const Trend trend = fit_trend(t, residual, max_lag);
  out.trend_per_s = trend.slope;
  out.trend_std_error = trend.std_error;
  out.trend_variance_fraction = trend.variance_fraction;
  out.trend_significant = trend.significant;
  return out;
}

std::vector<Unexplained> unexplained_structure(const ResidualAnalysis& analysis, std::string axis) {
  std::vector<Unexplained> out;
  for (const SpectralPeak& peak : analysis.peaks) {
    if (peak.ignored) continue;
    Unexplained u;
    u.kind = "frequency";
    u.axis = axis;
    u.frequency_hz = peak.frequency_hz;
    u.value = peak.power_ratio;
    u.where = printf_string("line at %.2f Hz, %.0fx the local median power", peak.frequency_hz, peak.power_ratio);
    out.push_back(std::move(u));
  }
  for (const SignalCorrelation& c : analysis.correlations) {
    if (!c.significant) continue;
    Unexplained u;
    u.kind = "correlation";
    u.axis = axis;
    u.signal = c.signal;
    u.lag_s = c.lag_s;
    u.value = c.coefficient;
    u.where = c.signal +
              printf_string(" at lag %+.3f s, r=%.2f (significant above %.2f)", c.lag_s, c.coefficient, c.threshold);
    out.push_back(std::move(u));
  }
  if (analysis.trend_significant) {
    Unexplained u;
    u.kind = "trend";
    u.axis = axis;
    u.value = analysis.trend_per_s;
    u.where = printf_string("drift of %+.4g m/s^2 per s (%.1f standard errors, %.0f%% of the variance)",
                            analysis.trend_per_s, std::abs(analysis.trend_per_s) / analysis.trend_std_error,
                            100.0 * analysis.trend_variance_fraction);
    out.push_back(std::move(u));
  }
  // Not white, and nothing above (nor a line the caller chose to ignore) says where: point at the residual's own
  // strongest correlation beyond the lag spacing the whiteness test skips.
  if (!analysis.white && out.empty() && analysis.peaks.empty() && analysis.sample_rate_hz > 0.0) {
    const auto& acf = analysis.autocorrelation;
    const std::size_t first =
        std::max<std::size_t>(1, std::size_t(std::lround(analysis.ljung_box_lag_spacing_s * analysis.sample_rate_hz)));
    if (first < acf.size()) {
      std::size_t best = first;
      for (std::size_t k = first; k < acf.size(); ++k)
        if (std::abs(acf[k]) > std::abs(acf[best])) best = k;
      Unexplained u;
      u.kind = "autocorrelation";
      u.axis = axis;
      u.lag_s = double(best) / analysis.sample_rate_hz;
      u.value = acf[best];
      const std::string p = analysis.ljung_box_p < 1e-6 ? "p<1e-6" : printf_string("p=%.2g", analysis.ljung_box_p);
      u.where = printf_string(
          "not white (Ljung-Box %s) with no line, signal or trend to blame; strongest "
          "self-correlation rho=%.2f at lag %.3f s",
          p.c_str(), acf[best], u.lag_s);
      out.push_back(std::move(u));
    }
  }
  return out;
}

}  // namespace imubridge::diagnose
