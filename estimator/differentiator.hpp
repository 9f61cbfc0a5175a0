#pragma once
// Angular acceleration from the gyro. Offline fits use the non-causal central difference (no delay); live
// estimation uses the causal least-squares slope, whose response and delay are derived in docs/estimator.md.
#include <Eigen/Core>
#include <array>
#include <optional>
#include <span>
#include <vector>

namespace imubridge::estimator {

// x'_k = (x_{k+1} - x_{k-1}) / (t_{k+1} - t_{k-1}), one-sided differences at the two ends, zero for a single sample.
// Throws std::invalid_argument when the lengths differ.
std::vector<Eigen::Vector3d> central_difference(std::span<const double> t, std::span<const Eigen::Vector3d> x);

// Least-squares slope of the last N samples (N odd). At a uniform period h it is a linear-phase FIR differentiator
// delayed by exactly (N-1)/2 samples: its output at t_k is the derivative at t_k - (N-1)/2 * h, the window's centre.
// It fits against the samples' own times, so timestamp jitter and a missing sample bias it only slightly.
class CausalDifferentiator {
 public:
  static constexpr int kMaxWindow = 31;

  // window: odd, 3..kMaxWindow; throws std::invalid_argument otherwise.
  explicit CausalDifferentiator(int window);

  // Adds a sample and returns the slope once `window` samples are held. The caller guarantees t increases.
  std::optional<Eigen::Vector3d> update(double t, const Eigen::Vector3d& x);
  void reset() { count_ = head_ = 0; }

  int window() const { return window_; }
  int delay_samples() const { return (window_ - 1) / 2; }

 private:
  int window_;
  int count_ = 0;  // samples held, at most window_
  int head_ = 0;   // where the next sample goes
  std::array<double, kMaxWindow> t_{};
  std::array<Eigen::Vector3d, kMaxWindow> x_{};
};

}  // namespace imubridge::estimator
