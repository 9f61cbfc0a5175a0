#include "estimator/reference_delay.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <utility>
#include <vector>

#include "estimator/constants.hpp"
#include "estimator/on_threads.hpp"

namespace imubridge::estimator {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

std::string format(const char* pattern, double a, double b = 0.0) {
  char buffer[160];
  std::snprintf(buffer, sizeof buffer, pattern, a, b);
  return buffer;
}

// The IMU's horizontal NED acceleration integrated over time (trapezoids), so the mean over any interval is a
// difference of two interpolated values; and the gyro and attitude there, for the lever arm's share.
struct ImuSide {
  const ImuSeries& s;
  std::vector<Vector2d> c;

  explicit ImuSide(const ImuSeries& series) : s(series), c(series.size(), Vector2d::Zero()) {
    const Vector3d g(0.0, 0.0, kGravity);
    Vector2d previous = Vector2d::Zero();
    for (std::size_t k = 0; k < s.size(); ++k) {
      const Vector2d a = (s.reference->attitude[k] * s.accel[k] + g).head<2>();
      if (k > 0) c[k] = c[k - 1] + 0.5 * (previous + a) * (s.t[k] - s.t[k - 1]);
      previous = a;
    }
  }
  // Where tau falls: the sample pair around it and where between them (clamped to the data). `hint` is the first
  // sample after the previous tau asked with it: the lags move each box by a step or so, so walking from there finds
  // the same pair as a search over the whole series (std::upper_bound) at a fraction of the cost.
  struct Place {
    std::size_t i;
    double f;
  };
  Place locate(double tau, std::size_t& hint) const {
    std::size_t after = std::min(hint, s.size());  // the first sample later than tau
    while (after > 0 && s.t[after - 1] > tau) --after;
    while (after < s.size() && !(s.t[after] > tau)) ++after;
    hint = after;
    const std::size_t i = std::clamp<std::size_t>(after, 1, s.size() - 1);
    return {i, std::clamp((tau - s.t[i - 1]) / (s.t[i] - s.t[i - 1]), 0.0, 1.0)};
  }
  Vector2d integral(const Place& p) const { return c[p.i - 1] + p.f * (c[p.i] - c[p.i - 1]); }
  Vector3d gyro(const Place& p) const { return s.gyro[p.i - 1] + p.f * (s.gyro[p.i] - s.gyro[p.i - 1]); }
  Eigen::Matrix3d attitude(const Place& p) const {
    return s.reference->attitude[p.f < 0.5 ? p.i - 1 : p.i].toRotationMatrix();
  }
};

Eigen::Matrix3d skew(const Vector3d& w) {
  Eigen::Matrix3d m;
  m << 0.0, -w.z(), w.y(), w.z(), 0.0, -w.x(), -w.y(), w.x(), 0.0;
  return m;
}

// The correlation of x and y (stacked north, east of every box) once the columns of `n` are projected out of both:
// a partial correlation. With n holding the means and the lever arm's tangential term, an IMU far from the mass
// centre on an agile airframe (where w_dot x r dominates the specific force) still correlates at the right lag.
double partial_correlation(const Eigen::VectorXd& x, const Eigen::VectorXd& y, const Eigen::MatrixXd& n) {
  const Eigen::LDLT<Eigen::MatrixXd> normal(n.transpose() * n);
  const Eigen::VectorXd px = x - n * normal.solve(n.transpose() * x);
  const Eigen::VectorXd py = y - n * normal.solve(n.transpose() * y);
  const double norms = px.norm() * py.norm();
  return norms > 0.0 ? px.dot(py) / norms : 0.0;
}

struct Box {
  double t0, t1;
  Vector2d accel;  // the reference's mean horizontal acceleration over [t0, t1]
};

// The reference's intervals of at least kDelayBoxSeconds, stepping by about half of one, inside the IMU's data even
// when moved by the largest lag; an interval spanning a gap in the reference is left out.
std::vector<Box> reference_boxes(std::span<const double> t, std::span<const Vector3d> v, double imu_start,
                                 double imu_end) {
  std::vector<double> steps;
  for (std::size_t i = 1; i < t.size(); ++i) steps.push_back(t[i] - t[i - 1]);
  if (steps.empty()) return {};
  std::nth_element(steps.begin(), steps.begin() + static_cast<long>(steps.size() / 2), steps.end());
  const double typical_step = steps[steps.size() / 2];
  const double longest = std::max(kDelayBoxSeconds, typical_step) + 2.0 * typical_step;
  std::vector<Box> boxes;
  std::size_t i = 0;
  while (i + 1 < t.size()) {
    std::size_t j = i + 1;
    while (j + 1 < t.size() && t[j] - t[i] < kDelayBoxSeconds) ++j;
    if (t[j] - t[i] < kDelayBoxSeconds) break;  // the last, short interval
    const double span = t[j] - t[i];
    if (span <= longest && t[i] - kMaxReferenceDelay >= imu_start && t[j] + kMaxReferenceDelay <= imu_end)
      boxes.push_back({t[i], t[j], (v[j] - v[i]).head<2>() / span});
    std::size_t next = i + 1;
    while (next < j && t[next] - t[i] < 0.5 * span) ++next;
    i = next;
  }
  return boxes;
}

// Lags a thread takes at a time. Each box is placed at all of them before the next box, its samples still in the
// cache (an eighth less time than one lag at a time on EuRoC MH_01).
constexpr int kLagsPerRun = 8;

// One thread's working space for correlate_lags: the IMU's side of every box at each lag of a run, and where each
// box last found itself in the IMU's samples (its start, end and middle), where the next lag's search begins.
struct LagScratch {
  explicit LagScratch(std::size_t boxes)
      : y(kLagsPerRun, Eigen::VectorXd(static_cast<Eigen::Index>(2 * boxes))),
        n(kLagsPerRun, Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(2 * boxes), 5)),
        hints(boxes, {0, 0, 0}) {}
  std::vector<Eigen::VectorXd> y;
  // Nuisance columns: a constant north and east (a tilt or bias), and the lever arm's tangential acceleration
  // R (w_dot x r) = R skew(w_dot) r, linear in the unknown lever arm r.
  std::vector<Eigen::MatrixXd> n;
  std::vector<std::array<std::size_t, 3>> hints;
  bool placed = false;  // the hints hold places found at an earlier lag
};

// The partial correlation of the reference's box accelerations `x` with the IMU's at lags k * kDelayLagStep, k in
// [first, last) (at most kLagsPerRun of them), into rho[k + half].
void correlate_lags(const ImuSide& imu, const std::vector<Box>& boxes, const Eigen::VectorXd& x, int first, int last,
                    int half, std::vector<double>& rho, LagScratch& scratch) {
  for (std::size_t b = 0; b < boxes.size(); ++b) {
    std::array<std::size_t, 3>& hint = scratch.hints[b];
    // Unplaced, a box starts from where the box before it stands (boxes are in time order), not from the first
    // sample: walking every box up from there was most of the estimate's time.
    if (!scratch.placed && b > 0) hint = scratch.hints[b - 1];
    const auto row = static_cast<Eigen::Index>(2 * b);
    for (int k = first; k < last; ++k) {
      Eigen::VectorXd& y = scratch.y[static_cast<std::size_t>(k - first)];
      Eigen::MatrixXd& n = scratch.n[static_cast<std::size_t>(k - first)];
      // The reference stamped t describes the vehicle at t - lag.
      const double lag = k * kDelayLagStep;
      const double t0 = boxes[b].t0 - lag, t1 = boxes[b].t1 - lag, span = t1 - t0;
      const ImuSide::Place start = imu.locate(t0, hint[0]), end = imu.locate(t1, hint[1]);
      y.segment<2>(row) = (imu.integral(end) - imu.integral(start)) / span;
      const Vector3d w_dot = (imu.gyro(end) - imu.gyro(start)) / span;
      // times r: R (w_dot x r)
      const Eigen::Matrix3d tangential = imu.attitude(imu.locate(0.5 * (t0 + t1), hint[2])) * skew(w_dot);
      n.block<2, 3>(row, 0) = tangential.topRows<2>();
      n(row, 3) = 1.0;
      n(row + 1, 4) = 1.0;
    }
  }
  scratch.placed = true;
  for (int k = first; k < last; ++k) {
    const auto i = static_cast<std::size_t>(k - first);
    rho[static_cast<std::size_t>(k + half)] = partial_correlation(x, scratch.y[i], scratch.n[i]);
  }
}

// The partial correlation at every lag, -half .. half steps. The lags are independent: the threads take runs of them
// as they come free, each with a scratch of its own, and rho is the same numbers however they were shared.
std::vector<double> correlations(const ImuSeries& series, const std::vector<Box>& boxes, int half) {
  const ImuSide imu(series);
  Eigen::VectorXd x(static_cast<Eigen::Index>(2 * boxes.size()));
  for (std::size_t b = 0; b < boxes.size(); ++b) x.segment<2>(static_cast<Eigen::Index>(2 * b)) = boxes[b].accel;
  std::vector<double> rho(static_cast<std::size_t>(2 * half + 1));
  std::atomic<int> next{-half};
  on_threads(std::min(cores(), 8u), [&](std::size_t) {
    LagScratch scratch(boxes.size());
    for (int first = next.fetch_add(kLagsPerRun); first <= half; first = next.fetch_add(kLagsPerRun))
      correlate_lags(imu, boxes, x, first, std::min(first + kLagsPerRun, half + 1), half, rho, scratch);
  });
  return rho;
}

// The best lag and the peak's curvature, and why the lag is not to be used when it is not.
void judge_peak(const std::vector<double>& rho, int half, ReferenceDelay& out) {
  const std::size_t best = static_cast<std::size_t>(std::max_element(rho.begin(), rho.end()) - rho.begin());
  const double lag_of_best = (static_cast<double>(best) - half) * kDelayLagStep;
  out.delay_s = lag_of_best;
  out.correlation = rho[best];
  if (best == 0 || best + 1 == rho.size()) {
    out.unusable = format("the best match is at the edge of the +-%.1f s searched", kMaxReferenceDelay);
    return;
  }
  // The parabola through the best candidate and its neighbours: its vertex, and its curvature.
  const double lo = rho[best - 1], mid = rho[best], hi = rho[best + 1];
  const double second = lo - 2.0 * mid + hi;
  if (second < 0.0) {
    const double offset = std::clamp(0.5 * (lo - hi) / second, -0.5, 0.5);
    out.delay_s = lag_of_best + offset * kDelayLagStep;
    out.correlation = mid - 0.25 * (lo - hi) * offset;
  }
  out.curvature = -second / (kDelayLagStep * kDelayLagStep);
  if (out.acceleration_rms < kMinDelayAcceleration) {
    out.unusable = format("the vehicle hardly accelerates: %.3f m/s^2 RMS horizontally, %.2f needed",
                          out.acceleration_rms, kMinDelayAcceleration);
  } else if (out.correlation < kMinDelayCorrelation) {
    out.unusable =
        format("the accelerations correlate %.2f at best, %.2f needed", out.correlation, kMinDelayCorrelation);
  } else {
    // A second peak nearly as high, away from the first one's flanks, makes the lag ambiguous.
    const auto away = static_cast<std::size_t>(std::lround(kDelayBoxSeconds / kDelayLagStep / 2.0));
    for (std::size_t k = 1; k + 1 < rho.size(); ++k) {
      const bool local_max = rho[k] >= rho[k - 1] && rho[k] >= rho[k + 1];
      const std::size_t distance = k > best ? k - best : best - k;
      // A peak of its own: the correlation dips between the two by more than the ambiguity (else a bump on the
      // best peak's broad flank).
      const double dip = *std::min_element(rho.begin() + static_cast<long>(std::min(k, best)),
                                           rho.begin() + static_cast<long>(std::max(k, best)) + 1);
      if (local_max && distance > away && rho[k] >= rho[best] - kDelayAmbiguity && rho[k] - dip > kDelayAmbiguity) {
        out.unusable = format("two lags match nearly as well, %.3f and %.3f s", lag_of_best,
                              (static_cast<double>(k) - half) * kDelayLagStep);
        break;
      }
    }
  }
}

}  // namespace

std::string describe(const ReferenceDelay& d) {
  if (d.usable()) return format("%.3f s (correlation %.2f)", d.delay_s, d.correlation);
  if (d.boxes == 0) return "cannot be estimated (" + *d.unusable + ")";
  return "cannot be estimated (" + *d.unusable +
         format("; best match %.3f s at correlation %.2f)", d.delay_s, d.correlation);
}

ReferenceDelay estimate_reference_delay(const ImuSeries& series, std::span<const double> reference_t,
                                        std::span<const Vector3d> reference_velocity_ned) {
  if (!series.reference || series.reference->attitude.size() != series.size())
    throw std::invalid_argument("estimate_reference_delay: the series has no reference attitude at every sample");
  if (reference_t.size() != reference_velocity_ned.size())
    throw std::invalid_argument("estimate_reference_delay: reference times and velocities differ in length");
  ReferenceDelay out;
  if (series.size() < 2) {
    out.unusable = "too few IMU samples";
    return out;
  }
  const std::vector<Box> boxes =
      reference_boxes(reference_t, reference_velocity_ned, series.t.front(), series.t.back());
  out.boxes = boxes.size();
  if (boxes.size() < kMinDelayBoxes) {
    out.boxes = 0;
    out.unusable = "too little reference data: " + std::to_string(boxes.size()) + " intervals of at least " +
                   format("%.1f s", kDelayBoxSeconds) + ", " + std::to_string(kMinDelayBoxes) + " needed";
    return out;
  }
  Vector2d mean_ref = Vector2d::Zero();
  for (const Box& b : boxes) mean_ref += b.accel;
  mean_ref /= static_cast<double>(boxes.size());
  double ref_square = 0.0;
  for (const Box& b : boxes) ref_square += (b.accel - mean_ref).squaredNorm();
  out.acceleration_rms = std::sqrt(ref_square / static_cast<double>(boxes.size()));

  const int half = static_cast<int>(std::lround(kMaxReferenceDelay / kDelayLagStep));
  judge_peak(correlations(series, boxes, half), half, out);
  return out;
}

}  // namespace imubridge::estimator
