#include "diagnose/gyro_against_reference.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <cmath>
#include <vector>

#include "diagnose/search.hpp"
#include "diagnose/signals.hpp"
#include "estimator/imu_axes.hpp"

namespace imubridge::diagnose {

using Eigen::Vector3d;

std::optional<GyroAgainstReference> gyro_against_reference(const Signals& signals, std::size_t first,
                                                           std::size_t count) {
  if (!signals.reference) return std::nullopt;
  // Per span: the rotation the gyro integrates less the reference's, per second (rad/s), and the reference's rate.
  // As rotation vectors, the gyro's turn read in a frame R turned from the reference's is exactly R times the
  // reference's (Log(R A R^T) = R Log(A)), so the difference is linear in the turn: a frame turned slightly reads as m
  // below at any rate, never as a bias.
  std::vector<Vector3d> excess, rate;
  for (const estimator::SpanRotation& s : estimator::span_rotations(
           signals.t, signals.gyro, signals.reference->attitude, first, first + count, kGyroSpanSeconds)) {
    const Vector3d e = (s.gyro - s.reference) / s.seconds, w = s.reference / s.seconds;
    if (e.allFinite() && w.allFinite()) excess.push_back(e), rate.push_back(w);
  }
  const std::size_t n = excess.size();
  if (n < kGyroMinSpans) return std::nullopt;
  Eigen::MatrixXd design(n, 4);
  for (std::size_t k = 0; k < n; ++k) design.row(static_cast<Eigen::Index>(k)) << 1.0, rate[k].transpose();
  // A flight that turns about fewer than three axes leaves some of m undetermined: pseudo-inverse of the normal
  // equations, so that the bias (the intercept) is still estimated from what the spans determine.
  const Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> normal(design.transpose() * design);
  const Eigen::MatrixXd normal_inverse = normal.pseudoInverse();
  const double dof = std::max(static_cast<double>(n) - static_cast<double>(normal.rank()), 1.0);
  GyroAgainstReference out;
  out.spans = n;
  for (int axis = 0; axis < 3; ++axis) {
    Eigen::VectorXd y(n);
    for (std::size_t k = 0; k < n; ++k) y[static_cast<Eigen::Index>(k)] = excess[k][axis];
    const Eigen::VectorXd c = normal_inverse * (design.transpose() * y);
    const Eigen::VectorXd residual = y - design * c;
    // The spans' residuals correlate where the reference's own filtering or delay spans several of them.
    const double n_eff = effective_samples({residual.data(), n}, n / 2);
    const double variance = residual.squaredNorm() / dof;
    out.bias[axis] = c[0];
    out.std_error[axis] = std::sqrt(variance * normal_inverse(0, 0) * static_cast<double>(n) / n_eff);
  }
  out.statistic = out.bias.cwiseQuotient(out.std_error).squaredNorm();
  if (!std::isfinite(out.statistic)) return std::nullopt;
  out.p_value = boost::math::cdf(boost::math::complement(boost::math::chi_squared(3.0), out.statistic));
  return out;
}

}  // namespace imubridge::diagnose
