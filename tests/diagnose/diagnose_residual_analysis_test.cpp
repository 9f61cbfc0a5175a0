#include "diagnose/residual_analysis.hpp"

#include <gtest/gtest.h>

#include <boost/math/distributions/normal.hpp>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <vector>

#include "sim/random.hpp"

namespace imubridge::diagnose {
namespace {

constexpr double kRate = 200.0;   // Hz
constexpr double kWindow = 30.0;  // s, a validation window as diagnose uses it
constexpr std::size_t kN = std::size_t(kRate * kWindow);

std::vector<double> times(std::size_t n = kN, double rate = kRate) {
  std::vector<double> t(n);
  for (std::size_t i = 0; i < n; ++i) t[i] = 100.0 + double(i) / rate;  // session time need not start at zero
  return t;
}

std::vector<double> white_noise(std::uint64_t seed, std::size_t n = kN) {
  sim::Rng rng(seed);
  std::vector<double> x(n);
  for (double& v : x) v = rng.normal();
  return x;
}

// Unit-variance first-order Gauss-Markov noise with time constant tau: what a sensor's low-pass filter does to white
// noise (tau of a few ms), or a smooth signal standing in for a gyro rate or a velocity (tau of a tenth of a second
// and more).
std::vector<double> ar1_noise(std::uint64_t seed, double tau, std::size_t n = kN, double rate = kRate) {
  const double phi = std::exp(-1.0 / (rate * tau));
  sim::Rng rng(seed);
  std::vector<double> x(n);
  double state = rng.normal();
  for (double& v : x) {
    state = phi * state + std::sqrt(1.0 - phi * phi) * rng.normal();
    v = state;
  }
  return x;
}

void add_sine(std::vector<double>& x, const std::vector<double>& t, double amplitude, double hz) {
  for (std::size_t i = 0; i < x.size(); ++i) x[i] += amplitude * std::sin(2.0 * std::numbers::pi * hz * t[i] + 0.4);
}

// A ramp of total height `range` across the window, centred on zero.
void add_drift(std::vector<double>& x, const std::vector<double>& t, double range) {
  const double t0 = t.front(), span = t.back() - t.front();
  for (std::size_t i = 0; i < x.size(); ++i) x[i] += range * ((t[i] - t0) / span - 0.5);
}

double bin_width(const ResidualAnalysis& a) { return a.frequency_hz[1] - a.frequency_hz[0]; }

TEST(ResidualAnalysis, WhiteNoiseShowsNoStructure) {
  const auto t = times();
  for (std::uint64_t seed : {1u, 2u, 3u}) {
    const std::vector<NamedSignal> candidates{{"independent_noise", white_noise(100 + seed)},
                                              {"smooth", ar1_noise(200 + seed, 0.3)},
                                              {"constant", std::vector<double>(kN, 9.81)}};
    const ResidualAnalysis a = analyse_residual(t, white_noise(seed), candidates, {});
    EXPECT_TRUE(a.white) << "seed " << seed << " p=" << a.ljung_box_p;
    EXPECT_TRUE(a.peaks.empty()) << "seed " << seed << " strongest at " << a.peaks.front().frequency_hz;
    ASSERT_EQ(a.correlations.size(), candidates.size());
    for (const SignalCorrelation& c : a.correlations) EXPECT_FALSE(c.significant) << c.signal << " r=" << c.coefficient;
    EXPECT_FALSE(a.trend_significant);
    EXPECT_TRUE(unexplained_structure(a, "x").empty());

    EXPECT_EQ(a.samples, kN);
    EXPECT_NEAR(a.sample_rate_hz, kRate, 1e-6);
    EXPECT_NEAR(a.rms, 1.0, 0.03);
    EXPECT_NEAR(a.mean, 0.0, 4.0 / std::sqrt(double(kN)));
    ASSERT_EQ(a.autocorrelation.size(), std::size_t(0.5 * kRate) + 1);  // max_lag_s at the sample rate, and lag 0
    EXPECT_EQ(a.autocorrelation[0], 1.0);
    EXPECT_NEAR(a.ljung_box_lag_spacing_s, kWhitenessLagSpacingS, 1e-12);
    EXPECT_EQ(a.ljung_box_lags, kMaxWhitenessLags);
  }
}

TEST(ResidualAnalysis, ShortFilterColourIsWhiteAtTheLagSpacingButDriftIsNot) {
  const auto t = times();
  for (std::uint64_t seed : {11u, 12u, 13u}) {
    // A 5 ms first-order filter at 200 Hz correlates neighbours (rho(1) = 0.37): the classical test rejects it.
    std::vector<double> coloured = ar1_noise(seed, 0.005);
    EXPECT_LT(ljung_box(coloured, kMaxWhitenessLags).p, 1e-6);
    const ResidualAnalysis a = analyse_residual(t, coloured, {}, {});
    EXPECT_TRUE(a.white) << "seed " << seed << " p=" << a.ljung_box_p;
    EXPECT_FALSE(a.trend_significant);

    add_drift(coloured, t, 1.0);  // one noise standard deviation over the window
    const ResidualAnalysis drifting = analyse_residual(t, coloured, {}, {});
    EXPECT_FALSE(drifting.white);
    EXPECT_TRUE(drifting.trend_significant);
  }
}

TEST(ResidualAnalysis, SinusoidInNoiseIsFoundAtItsFrequency) {
  const auto t = times();
  for (double hz : {2.3, 7.3, 61.7}) {
    std::vector<double> x = white_noise(21);
    add_sine(x, t, 0.7, hz);  // 0.7 noise standard deviations: invisible in the time series by eye
    const ResidualAnalysis a = analyse_residual(t, x, {}, {});
    ASSERT_FALSE(a.peaks.empty()) << hz << " Hz";
    EXPECT_NEAR(a.peaks.front().frequency_hz, hz, bin_width(a)) << hz << " Hz";
    EXPECT_LE(bin_width(a), 0.5);
    EXPECT_GT(bin_width(a), 0.25);
    EXPECT_GE(a.peaks.front().power_ratio, kPeakPowerRatio);
    EXPECT_FALSE(a.peaks.front().ignored);
    EXPECT_EQ(a.peaks.size(), 1u);
    EXPECT_FALSE(a.white);

    const std::vector<Unexplained> u = unexplained_structure(a, "y");
    ASSERT_FALSE(u.empty());
    EXPECT_EQ(u.front().kind, "frequency");
    EXPECT_EQ(u.front().axis, "y");
    EXPECT_NEAR(u.front().frequency_hz, hz, bin_width(a));
    EXPECT_NE(u.front().where.find("Hz"), std::string::npos);
  }
}

TEST(ResidualAnalysis, WeakLineAtTheLagSpacingsFrequencyStillFailsWhiteness) {
  // Decimating to 1/spacing would alias this line to DC and lose it; lags that are multiples of the spacing see it
  // as a constant correlation. Too weak (0.3 sigma) to stand out of the spectrum, but the whiteness test finds it.
  const auto t = times();
  std::vector<double> x = white_noise(31);
  add_sine(x, t, 0.3, 1.0 / kWhitenessLagSpacingS);
  const ResidualAnalysis a = analyse_residual(t, x, {}, {});
  EXPECT_TRUE(a.peaks.empty());
  EXPECT_FALSE(a.white);
  const std::vector<Unexplained> u = unexplained_structure(a, "x");
  ASSERT_EQ(u.size(), 1u);  // nothing else points at it, so the residual's own correlation does
  EXPECT_EQ(u.front().kind, "autocorrelation");
  EXPECT_GE(u.front().lag_s, kWhitenessLagSpacingS - 1e-9);
}

TEST(ResidualAnalysis, LineInAnIgnoredBandIsMarkedAndNotUnexplained) {
  const auto t = times();
  std::vector<double> x = white_noise(41);
  add_sine(x, t, 0.7, 37.3);
  AnalysisOptions options;
  options.ignore_bands = {{5.0, 6.0}, {36.0, 39.0}};
  const ResidualAnalysis a = analyse_residual(t, x, {}, options);
  ASSERT_EQ(a.peaks.size(), 1u);
  EXPECT_TRUE(a.peaks.front().ignored);
  EXPECT_FALSE(a.white);  // ignoring a band hides it from the line search only, not from the whiteness test
  EXPECT_TRUE(unexplained_structure(a, "x").empty());

  options.ignore_bands = {{38.0, 39.0}};
  const ResidualAnalysis outside = analyse_residual(t, x, {}, options);
  ASSERT_EQ(outside.peaks.size(), 1u);
  EXPECT_FALSE(outside.peaks.front().ignored);
  EXPECT_EQ(unexplained_structure(outside, "x").size(), 1u);
}

TEST(ResidualAnalysis, StrongLineIsOneLineNotItsSideLobes) {
  const auto t = times();
  std::vector<double> x = white_noise(51);
  for (double& v : x) v *= 0.01;
  add_sine(x, t, 1.0, 23.45);  // 40 dB over the noise: Hann side lobes reach far above the floor
  const ResidualAnalysis a = analyse_residual(t, x, {}, {});
  ASSERT_EQ(a.peaks.size(), 1u);
  EXPECT_NEAR(a.peaks.front().frequency_hz, 23.45, 0.25 * bin_width(a));  // the parabola refines within the bin
}

TEST(ResidualAnalysis, LaggedSignalIsFoundWithItsLagAndSign) {
  const auto t = times();
  const std::vector<double> signal = ar1_noise(61, 0.05);  // a smooth "gyro rate"-like signal
  const int shift = int(0.02 * kRate);
  std::vector<double> residual = white_noise(62);
  for (std::size_t i = 0; i < kN; ++i) residual[i] += 0.3 * signal[i >= std::size_t(shift) ? i - shift : 0];
  const std::vector<NamedSignal> candidates{{"unrelated", ar1_noise(63, 0.05)}, {"gyro_rate.y", signal}};
  const ResidualAnalysis a = analyse_residual(t, residual, candidates, {});
  ASSERT_EQ(a.correlations.size(), 2u);
  const SignalCorrelation& best = a.correlations.front();
  EXPECT_EQ(best.signal, "gyro_rate.y");
  EXPECT_NEAR(best.lag_s, 0.02, 1e-9);  // positive: the residual lags the signal
  double mean = 0.0, variance = 0.0;    // the smooth signal's own sample variance over 30 s differs from 1
  for (double v : signal) mean += v / double(kN);
  for (double v : signal) variance += (v - mean) * (v - mean) / double(kN);
  EXPECT_NEAR(best.coefficient, 0.3 * std::sqrt(variance) / std::sqrt(0.09 * variance + 1.0), 0.03);
  EXPECT_TRUE(best.significant);
  EXPECT_GT(best.coefficient, best.threshold);
  EXPECT_FALSE(a.correlations.back().significant);

  const std::vector<Unexplained> u = unexplained_structure(a, "x");
  ASSERT_EQ(u.size(), 1u);
  EXPECT_EQ(u.front().kind, "correlation");
  EXPECT_EQ(u.front().signal, "gyro_rate.y");
  EXPECT_NEAR(u.front().lag_s, 0.02, 1e-9);
  EXPECT_NE(u.front().where.find("+0.020 s"), std::string::npos) << u.front().where;

  // The residual leading the signal, with the opposite sign.
  std::vector<double> leading = white_noise(64);
  for (std::size_t i = 0; i < kN; ++i) leading[i] -= 0.3 * signal[std::min(kN - 1, i + 6)];
  const SignalCorrelation lead = best_lagged_correlation(leading, candidates[1], kRate, 100, 0.01, 201);
  EXPECT_NEAR(lead.lag_s, -0.03, 1e-9);
  EXPECT_LT(lead.coefficient, -0.2);
  EXPECT_TRUE(lead.significant);
}

TEST(ResidualAnalysis, CorrelationThresholdAccountsForBothSeriesMemory) {
  const NamedSignal white{"white", white_noise(71)};
  const double z =
      boost::math::quantile(boost::math::complement(boost::math::normal_distribution<double>(), 0.01 / 201 / 2));
  const SignalCorrelation plain = best_lagged_correlation(white_noise(72), white, kRate, 100, 0.01, 201);
  EXPECT_NEAR(plain.threshold, z / std::sqrt(double(kN)), 0.05 * z / std::sqrt(double(kN)));

  // Two independent slowly varying series correlate by chance far more than white ones do; a threshold from the
  // plain sample size would call that significant.
  int beyond_naive = 0;
  for (std::uint64_t seed : {73u, 74u, 75u, 76u, 77u}) {
    const NamedSignal smooth{"smooth", ar1_noise(seed, 0.4)};
    const SignalCorrelation c = best_lagged_correlation(ar1_noise(seed + 100, 0.4), smooth, kRate, 100, 0.01, 201);
    EXPECT_GT(c.threshold, 3.0 * plain.threshold);
    EXPECT_FALSE(c.significant) << "seed " << seed << " r=" << c.coefficient;
    beyond_naive += std::abs(c.coefficient) > plain.threshold;
  }
  EXPECT_GT(beyond_naive, 0);
}

TEST(ResidualAnalysis, TrendIsDetectedWhenMaterial) {
  const auto t = times();
  std::vector<double> x = white_noise(81);
  add_drift(x, t, 1.0);
  const ResidualAnalysis a = analyse_residual(t, x, {}, {});
  EXPECT_TRUE(a.trend_significant);
  EXPECT_NEAR(a.trend_per_s, 1.0 / (t.back() - t.front()), 3.0 * a.trend_std_error);
  EXPECT_GT(a.trend_variance_fraction, kMaterialTrendFraction);
  const std::vector<Unexplained> u = unexplained_structure(a, "x");
  ASSERT_FALSE(u.empty());
  EXPECT_EQ(u.back().kind, "trend");
  EXPECT_DOUBLE_EQ(u.back().value, a.trend_per_s);

  // Many standard errors away from zero, yet less than 1 % of the variance: not worth reporting.
  std::vector<double> slight = white_noise(82);
  add_drift(slight, t, 0.25);
  const ResidualAnalysis b = analyse_residual(t, slight, {}, {});
  EXPECT_GT(std::abs(b.trend_per_s), 3.0 * b.trend_std_error);
  EXPECT_LT(b.trend_variance_fraction, kMaterialTrendFraction);
  EXPECT_FALSE(b.trend_significant);
}

TEST(ResidualAnalysis, TrendErrorWidensWithTheResidualsMemory) {
  const auto t = times();
  const ResidualAnalysis white = analyse_residual(t, white_noise(91), {}, {});
  const ResidualAnalysis red = analyse_residual(t, ar1_noise(92, 0.05), {}, {});
  // Bartlett with a ramp: the error grows by about sqrt((1 + phi) / (1 - phi)) = sqrt(2 tau * rate) for tau >> dt.
  EXPECT_NEAR(red.trend_std_error / white.trend_std_error, std::sqrt(2.0 * 0.05 * kRate), 0.6);
}

TEST(WelchPsd, WhiteNoiseIsFlatAndIntegratesToItsVariance) {
  for (double rate : {200.0, 1000.0}) {
    const std::size_t n = std::size_t(rate * 20.0);
    const std::vector<double> x = white_noise(101, n);
    const Spectrum s = welch_psd(x, rate);
    const double resolution = s.frequency_hz[1];
    EXPECT_GT(resolution, 0.25);
    EXPECT_LE(resolution, 0.5);
    EXPECT_DOUBLE_EQ(s.frequency_hz.back(), rate / 2.0);
    double sum = 0.0, integral = 0.0;
    for (std::size_t k = 1; k + 1 < s.psd.size(); ++k) {
      sum += s.psd[k];
      integral += s.psd[k] * resolution;
    }
    EXPECT_NEAR(sum / double(s.psd.size() - 2), 2.0 / rate, 0.03 * 2.0 / rate);  // one-sided level 2 sigma^2 / rate
    EXPECT_NEAR(integral, 1.0, 0.03);
  }
  // A short series gets shorter segments: at least four fit.
  const Spectrum short_one = welch_psd(white_noise(102, 100), kRate);
  EXPECT_EQ(short_one.psd.size(), 16u / 2 + 1);
}

TEST(ResidualAnalysis, SampleRateIsTheMedianStep) {
  std::vector<double> t = times(1000);
  for (std::size_t i = 500; i < t.size(); ++i) t[i] += 0.3;  // a gap, as a dropped packet burst leaves
  EXPECT_NEAR(sample_rate_hz(t), kRate, 1e-6);
}

TEST(ResidualAnalysis, SameInputSameOutput) {
  const auto t = times();
  std::vector<double> x = ar1_noise(111, 0.01);
  add_sine(x, t, 0.5, 12.0);
  const std::vector<NamedSignal> candidates{{"a", ar1_noise(112, 0.1)}, {"b", white_noise(113)}};
  const ResidualAnalysis a = analyse_residual(t, x, candidates, {});
  const ResidualAnalysis b = analyse_residual(t, x, candidates, {});
  EXPECT_EQ(a.psd, b.psd);
  EXPECT_EQ(a.autocorrelation, b.autocorrelation);
  EXPECT_EQ(a.ljung_box_q, b.ljung_box_q);
  ASSERT_EQ(a.correlations.size(), b.correlations.size());
  for (std::size_t i = 0; i < a.correlations.size(); ++i)
    EXPECT_EQ(a.correlations[i].coefficient, b.correlations[i].coefficient);
  EXPECT_EQ(a.trend_per_s, b.trend_per_s);
}

TEST(ResidualAnalysis, BadInputThrows) {
  const auto t = times(200);
  const std::vector<double> x = white_noise(121, 200);
  const std::vector<NamedSignal> none;
  EXPECT_THROW(analyse_residual(times(63), white_noise(1, 63), none, {}), std::invalid_argument);
  EXPECT_THROW(analyse_residual(times(199), x, none, {}), std::invalid_argument);
  const std::vector<NamedSignal> short_candidate{{"gyro.x", std::vector<double>(199, 0.0)}};
  EXPECT_THROW(analyse_residual(t, x, short_candidate, {}), std::invalid_argument);
  const std::vector<NamedSignal> nan_candidate{{"gyro.x", std::vector<double>(200, std::nan(""))}};
  EXPECT_THROW(analyse_residual(t, x, nan_candidate, {}), std::invalid_argument);
  std::vector<double> with_nan = x;
  with_nan[7] = std::numeric_limits<double>::infinity();
  EXPECT_THROW(analyse_residual(t, with_nan, none, {}), std::invalid_argument);
  EXPECT_THROW(analyse_residual(std::vector<double>(200, 1.0), x, none, {}), std::invalid_argument);

  AnalysisOptions bad;
  bad.max_lag_s = -0.1;
  EXPECT_THROW(analyse_residual(t, x, none, bad), std::invalid_argument);
  bad = {};
  bad.significance = 0.0;
  EXPECT_THROW(analyse_residual(t, x, none, bad), std::invalid_argument);
  bad = {};
  bad.acf_lags = -1;
  EXPECT_THROW(analyse_residual(t, x, none, bad), std::invalid_argument);
  bad = {};
  bad.ignore_bands = {{40.0, 30.0}};
  EXPECT_THROW(analyse_residual(t, x, none, bad), std::invalid_argument);

  EXPECT_THROW(ljung_box(x, 20, 10), std::invalid_argument);  // lag 200 of 200 samples
  EXPECT_THROW(ljung_box(x, 0), std::invalid_argument);
  EXPECT_THROW(welch_psd(white_noise(1, 15), kRate), std::invalid_argument);
}

}  // namespace
}  // namespace imubridge::diagnose
