#include "estimator/differentiator.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <numbers>
#include <random>
#include <vector>

namespace imubridge::estimator {
namespace {

constexpr double kH = 0.01;  // s, 100 Hz
constexpr int kN = 2000;

// x(t) = sum a_i sin(2 pi f_i t + phi_i) on each axis (the axes get different phases), with exact derivatives.
struct SumOfSines {
  std::vector<double> a{1.0, 0.5, 0.2};
  std::vector<double> f{0.4, 1.1, 2.3};
  std::vector<double> phi{0.3, 1.7, -0.8};

  Eigen::Vector3d derivative(double t, int order) const {
    Eigen::Vector3d out = Eigen::Vector3d::Zero();
    for (int axis = 0; axis < 3; ++axis) {
      for (std::size_t i = 0; i < a.size(); ++i) {
        const double w = 2.0 * std::numbers::pi * f[i];
        out[axis] += a[i] * std::pow(w, order) * std::sin(w * t + phi[i] + axis + order * std::numbers::pi / 2.0);
      }
    }
    return out;
  }
  double third_derivative_bound() const {
    double sum = 0.0;
    for (std::size_t i = 0; i < a.size(); ++i) sum += a[i] * std::pow(2.0 * std::numbers::pi * f[i], 3);
    return sum;
  }
};

std::vector<double> uniform_times() {
  std::vector<double> t(kN);
  for (int k = 0; k < kN; ++k) t[k] = 100.0 + k * kH;  // an offset start, as a session clock has
  return t;
}

std::vector<Eigen::Vector3d> white_noise(double sigma, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, sigma);
  std::vector<Eigen::Vector3d> noise(kN);
  for (auto& n : noise) n = {normal(rng), normal(rng), normal(rng)};
  return noise;
}

// Causal outputs aligned with their input index (nullopt during warm-up stays zero and is skipped by callers).
std::vector<Eigen::Vector3d> run_causal(int window, const std::vector<double>& t,
                                        const std::vector<Eigen::Vector3d>& x) {
  CausalDifferentiator d(window);
  std::vector<Eigen::Vector3d> out(x.size(), Eigen::Vector3d::Zero());
  for (std::size_t k = 0; k < x.size(); ++k) {
    if (auto slope = d.update(t[k], x[k])) out[k] = *slope;
  }
  return out;
}

double rms(const std::vector<Eigen::Vector3d>& e, std::size_t begin, std::size_t end) {
  double sum = 0.0;
  for (std::size_t k = begin; k < end; ++k) sum += e[k].squaredNorm();
  return std::sqrt(sum / (3.0 * static_cast<double>(end - begin)));
}

// Least-squares slope over N samples: weights b_u = u / (h S), u = -(N-1)/2 .. (N-1)/2, S = sum u^2 = N(N^2-1)/12.
double sum_u_squared(int n) { return n * (n * n - 1) / 12.0; }
double sum_u_fourth(int n) {
  double s = 0.0;
  for (int u = -(n - 1) / 2; u <= (n - 1) / 2; ++u) s += std::pow(u, 4);
  return s;
}

// Taylor's remainder bounds the error on a smooth signal by h^2 * sum u^4 / (6 S) * max|x'''| (the weights cancel
// the constant and quadratic terms and pass the linear one exactly). N = 3 is the central difference's h^2/6.
double truncation_bound(int n, double x3) { return kH * kH * sum_u_fourth(n) / (6.0 * sum_u_squared(n)) * x3; }

TEST(CentralDifference, MatchesAnalyticDerivativeWithinTruncationAndNoise) {
  const SumOfSines s;
  const auto t = uniform_times();
  const double sigma = 0.002;
  const auto noise = white_noise(sigma, 1);
  std::vector<Eigen::Vector3d> clean(kN), noisy(kN), truth(kN);
  for (int k = 0; k < kN; ++k) {
    clean[k] = s.derivative(t[k], 0);
    noisy[k] = clean[k] + noise[k];
    truth[k] = s.derivative(t[k], 1);
  }
  // Interior only: the ends are first-order one-sided differences.
  auto error = central_difference(t, clean);
  for (int k = 0; k < kN; ++k) error[k] -= truth[k];
  double worst = 0.0;
  for (int k = 1; k + 1 < kN; ++k) worst = std::max(worst, error[k].cwiseAbs().maxCoeff());
  const double truncation = truncation_bound(3, s.third_derivative_bound());
  EXPECT_LE(worst, truncation);
  EXPECT_GT(worst, 0.1 * truncation);  // the bound is tight, not vacuous

  // The filter is linear, so its noise output is the noise differentiated: std sigma / (sqrt(2) h).
  const double noise_gain = sigma / (std::sqrt(2.0) * kH);
  EXPECT_NEAR(rms(central_difference(t, noise), 1, kN - 1), noise_gain, 0.1 * noise_gain);
  auto total = central_difference(t, noisy);
  for (int k = 0; k < kN; ++k) total[k] -= truth[k];
  EXPECT_LE(rms(total, 1, kN - 1), truncation + 1.1 * noise_gain);
}

TEST(CentralDifference, ExactOnLinesWithUnevenSpacingAndAtTheEnds) {
  const std::vector<double> t{0.0, 0.01, 0.025, 0.03, 0.05};
  const Eigen::Vector3d slope(1.5, -2.0, 0.25);
  std::vector<Eigen::Vector3d> x;
  for (double ti : t) x.push_back(Eigen::Vector3d(1, 2, 3) + slope * ti);
  for (const auto& d : central_difference(t, x)) EXPECT_LT((d - slope).norm(), 1e-12);
}

TEST(CentralDifference, DegenerateInputs) {
  EXPECT_TRUE(central_difference({}, {}).empty());
  const std::vector<double> t{1.0};
  const std::vector<Eigen::Vector3d> x{Eigen::Vector3d(1, 2, 3)};
  EXPECT_EQ(central_difference(t, x)[0], Eigen::Vector3d::Zero());
  const std::vector<double> t2{1.0, 2.0};
  EXPECT_THROW(central_difference(t2, x), std::invalid_argument);
}

TEST(CausalDifferentiator, ShiftedByItsDelayMatchesAnalyticDerivative) {
  const SumOfSines s;
  const auto t = uniform_times();
  const double sigma = 0.002;
  const auto noise = white_noise(sigma, 2);
  for (int window : {5, 9}) {
    std::vector<Eigen::Vector3d> noisy(kN);
    for (int k = 0; k < kN; ++k) noisy[k] = s.derivative(t[k], 0) + noise[k];
    const auto out = run_causal(window, t, noisy);
    const double delay = (window - 1) / 2 * kH;

    std::vector<Eigen::Vector3d> shifted(kN), unshifted(kN);
    for (int k = 0; k < kN; ++k) {
      shifted[k] = out[k] - s.derivative(t[k] - delay, 1);
      unshifted[k] = out[k] - s.derivative(t[k], 1);
    }
    const double truncation = truncation_bound(window, s.third_derivative_bound());
    const double noise_gain = sigma / (kH * std::sqrt(sum_u_squared(window)));
    EXPECT_NEAR(rms(run_causal(window, t, noise), window, kN), noise_gain, 0.1 * noise_gain) << window;
    EXPECT_LE(rms(shifted, window, kN), truncation + 1.1 * noise_gain) << window;
    // Without the shift the delay shows: the documented delay is the real one.
    EXPECT_GT(rms(unshifted, window, kN), 3.0 * (truncation + 1.1 * noise_gain)) << window;
  }
}

TEST(CausalDifferentiator, SineResponseIsTheDocumentedFrequencyResponse) {
  // docs/estimator.md: H(W) = j e^{-j W c} / (h S) * sum_u u sin(W u), c = (N-1)/2, W = 2 pi f h.
  const int window = 7;
  const int c = (window - 1) / 2;
  for (double freq : {1.0, 7.0, 20.0}) {
    const double w = 2.0 * std::numbers::pi * freq * kH;
    double sum = 0.0;
    for (int u = -c; u <= c; ++u) sum += u * std::sin(w * u);
    const std::complex<double> h = std::complex<double>(0.0, 1.0) * std::exp(std::complex<double>(0.0, -w * c)) * sum /
                                   (kH * sum_u_squared(window));
    CausalDifferentiator d(window);
    for (int k = 0; k < 300; ++k) {
      // x_k = sin(W k) = Im(e^{j W k}); a real LTI filter maps it to Im(H e^{j W k}).
      const auto y = d.update(k * kH, Eigen::Vector3d::Constant(std::sin(w * k)));
      if (!y) continue;
      EXPECT_NEAR(y->x(), (h * std::exp(std::complex<double>(0.0, w * k))).imag(), 1e-9) << freq << " Hz, k " << k;
    }
  }
}

TEST(CausalDifferentiator, ExactOnLinesWithJitteredTimes) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> jitter(-0.004, 0.004);
  const Eigen::Vector3d slope(0.7, -1.2, 3.0);
  CausalDifferentiator d(5);
  for (int k = 0; k < 50; ++k) {
    const double t = k * kH + jitter(rng);
    if (auto y = d.update(t, Eigen::Vector3d(1, -1, 2) + slope * t)) {
      EXPECT_LT((*y - slope).norm(), 1e-9);
    }
  }
}

TEST(CausalDifferentiator, WarmsUpAndRestartsAfterReset) {
  CausalDifferentiator d(5);
  EXPECT_EQ(d.delay_samples(), 2);
  for (int round = 0; round < 2; ++round) {
    for (int k = 0; k < 4; ++k) EXPECT_FALSE(d.update(k, Eigen::Vector3d::Zero())) << k;
    EXPECT_TRUE(d.update(4, Eigen::Vector3d::Zero()));
    d.reset();
  }
}

TEST(CausalDifferentiator, RejectsUnusableWindows) {
  for (int window : {-1, 0, 1, 2, 4, CausalDifferentiator::kMaxWindow + 2})
    EXPECT_THROW(CausalDifferentiator{window}, std::invalid_argument) << window;
  EXPECT_NO_THROW(CausalDifferentiator{CausalDifferentiator::kMaxWindow});
}

}  // namespace
}  // namespace imubridge::estimator
