#include "estimator/differentiator.hpp"

#include <stdexcept>

namespace imubridge::estimator {

std::vector<Eigen::Vector3d> central_difference(std::span<const double> t, std::span<const Eigen::Vector3d> x) {
  if (t.size() != x.size()) throw std::invalid_argument("central_difference: t and x lengths differ");
  const std::size_t n = x.size();
  std::vector<Eigen::Vector3d> dx(n, Eigen::Vector3d::Zero());
  if (n < 2) return dx;
  dx.front() = (x[1] - x[0]) / (t[1] - t[0]);
  for (std::size_t k = 1; k + 1 < n; ++k) dx[k] = (x[k + 1] - x[k - 1]) / (t[k + 1] - t[k - 1]);
  dx.back() = (x[n - 1] - x[n - 2]) / (t[n - 1] - t[n - 2]);
  return dx;
}

CausalDifferentiator::CausalDifferentiator(int window) : window_(window) {
  if (window < 3 || window > kMaxWindow || window % 2 == 0)
    throw std::invalid_argument("CausalDifferentiator: window must be odd and in 3.." + std::to_string(kMaxWindow));
}

std::optional<Eigen::Vector3d> CausalDifferentiator::update(double t, const Eigen::Vector3d& x) {
  t_[head_] = t;
  x_[head_] = x;
  head_ = (head_ + 1) % window_;
  if (count_ < window_) ++count_;
  if (count_ < window_) return std::nullopt;

  // Times relative to the newest sample keep the sums well conditioned however large t grows.
  double t_mean = 0.0;
  Eigen::Vector3d x_mean = Eigen::Vector3d::Zero();
  for (int i = 0; i < window_; ++i) {
    t_mean += t_[i] - t;
    x_mean += x_[i];
  }
  t_mean /= window_;
  x_mean /= window_;
  double stt = 0.0;
  Eigen::Vector3d stx = Eigen::Vector3d::Zero();
  for (int i = 0; i < window_; ++i) {
    const double dt = t_[i] - t - t_mean;
    stt += dt * dt;
    stx += dt * (x_[i] - x_mean);
  }
  return stx / stt;
}

}  // namespace imubridge::estimator
