// The band limit of `diagnose --lowpass`: zero phase, unit gain in the band, strong rejection above it.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <vector>

#include "diagnose/lowpass.hpp"

namespace imubridge::diagnose {
namespace {

constexpr double kRate = 200.0;

std::vector<double> sine(double hz, double seconds, double amplitude = 1.0) {
  std::vector<double> x(static_cast<std::size_t>(seconds * kRate));
  for (std::size_t k = 0; k < x.size(); ++k) x[k] = amplitude * std::sin(2.0 * std::numbers::pi * hz * double(k) / kRate);
  return x;
}

double rms(const std::vector<double>& x, std::size_t skip) {
  double sum = 0.0;
  for (std::size_t k = skip; k < x.size() - skip; ++k) sum += x[k] * x[k];
  return std::sqrt(sum / double(x.size() - 2 * skip));
}

TEST(Lowpass, AConstantPassesUnchangedToTheLastBit) {
  std::vector<double> x(500, 9.81);
  zero_phase_lowpass(x, 10.0, kRate);
  for (double v : x) EXPECT_NEAR(v, 9.81, 1e-12);
}

TEST(Lowpass, ASlowSignalPassesWithoutDelayOrLoss) {
  const std::vector<double> original = sine(1.0, 10.0);
  std::vector<double> x = original;
  zero_phase_lowpass(x, 10.0, kRate);
  // Away from the ends: the same samples, to a fraction of a percent (gain at 1 Hz is 1 - 1e-4; no phase).
  for (std::size_t k = 200; k < x.size() - 200; ++k) EXPECT_NEAR(x[k], original[k], 2e-3) << k;
}

TEST(Lowpass, VibrationAboveTheCutoffIsRemoved) {
  std::vector<double> x = sine(37.0, 10.0, 0.5);
  zero_phase_lowpass(x, 10.0, kRate);
  // Fourth order at 3.7 times the cutoff: |H|^2 = 1 / (1 + 3.7^4) ~ 0.5 %.
  EXPECT_LT(rms(x, 100), 0.01 * 0.5 / std::sqrt(2.0));
  EXPECT_GT(rms(x, 100), 0.0);
}

TEST(Lowpass, TheCutoffMustLieInsideTheBand) {
  std::vector<double> x(10, 1.0);
  EXPECT_THROW(zero_phase_lowpass(x, 0.0, kRate), std::invalid_argument);
  EXPECT_THROW(zero_phase_lowpass(x, 100.0, kRate), std::invalid_argument);
  EXPECT_THROW(zero_phase_lowpass(x, -5.0, kRate), std::invalid_argument);
  std::vector<double> empty;
  EXPECT_NO_THROW(zero_phase_lowpass(empty, 10.0, kRate));
}

}  // namespace
}  // namespace imubridge::diagnose
