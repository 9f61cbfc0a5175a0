#include "diagnose/lowpass.hpp"

#include <cmath>
#include <numbers>
#include <stdexcept>

namespace imubridge::diagnose {
namespace {

struct Biquad {
  double b0, b1, b2, a1, a2;  // y[n] = b0 x[n] + b1 x[n-1] + b2 x[n-2] - a1 y[n-1] - a2 y[n-2]
};

Biquad butterworth(double cutoff_hz, double rate_hz) {
  const double k = std::tan(std::numbers::pi * cutoff_hz / rate_hz);  // pre-warped
  const double q = std::numbers::sqrt2 / 2.0;
  const double norm = 1.0 / (1.0 + k / q + k * k);
  const double b0 = k * k * norm;
  return {b0, 2.0 * b0, b0, 2.0 * (k * k - 1.0) * norm, (1.0 - k / q + k * k) * norm};
}

// One pass in the given direction, in transposed direct form II, started at the steady state of the first input.
template <typename Index>
void pass(std::span<double> x, const Biquad& f, Index first, Index step, std::size_t n) {
  const double x0 = x[static_cast<std::size_t>(first)];
  // Steady state for a constant input x0 (unit DC gain): y = x0.
  double z1 = x0 - f.b0 * x0;
  double z2 = f.b2 * x0 - f.a2 * x0;
  Index i = first;
  for (std::size_t k = 0; k < n; ++k, i += step) {
    const double in = x[static_cast<std::size_t>(i)];
    const double out = f.b0 * in + z1;
    z1 = f.b1 * in - f.a1 * out + z2;
    z2 = f.b2 * in - f.a2 * out;
    x[static_cast<std::size_t>(i)] = out;
  }
}

}  // namespace

void zero_phase_lowpass(std::span<double> x, double cutoff_hz, double rate_hz) {
  if (!(cutoff_hz > 0.0 && cutoff_hz < rate_hz / 2.0))
    throw std::invalid_argument("low-pass cutoff must lie between 0 and half the sample rate");
  if (x.empty()) return;
  const Biquad f = butterworth(cutoff_hz, rate_hz);
  const auto n = static_cast<std::ptrdiff_t>(x.size());
  pass<std::ptrdiff_t>(x, f, 0, 1, x.size());
  pass<std::ptrdiff_t>(x, f, n - 1, -1, x.size());
}

}  // namespace imubridge::diagnose
