#include "identification/velocity_scores.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "estimator/drag_velocity.hpp"
#include "estimator/lever_arm_compensation.hpp"
#include "estimator/velocity.hpp"

namespace imubridge::estimator {
namespace {

bool inside(double t, const TimeWindow& w) { return t >= w.start && t < w.end; }

// The reference's velocity in body axes (the series' axes, turned by `to_body` where given).
std::vector<Eigen::Vector3d> truth(const ImuSeries& series, const LeverArmCompensator* to_body = nullptr) {
  std::vector<Eigen::Vector3d> v = body_velocity(series.reference->attitude, series.reference->velocity_ned);
  if (to_body != nullptr) {
    for (Eigen::Vector3d& x : v) x = to_body->to_body(x);
  }
  return v;
}

VelocityError zero_error(const ImuSeries& series, const std::vector<Eigen::Vector3d>& v, const TimeWindow& w) {
  VelocityErrorSum sum;
  for (std::size_t k = 0; k < series.size(); ++k) {
    if (inside(series.t[k], w)) sum.add(v[k].head<2>());
  }
  return sum.rmse();
}

}  // namespace

VelocityScores zero_velocity_scores(const ImuSeries& series, const Eigen::Vector3d& mounting, const Windows& windows) {
  if (!series.reference) throw std::invalid_argument("zero velocity's error needs a reference");
  FullModelParams rotation_only;  // the compensator holds R_bs, the estimator's own frame
  rotation_only.mounting = mounting;
  const LeverArmCompensator to_body(rotation_only);
  const std::vector<Eigen::Vector3d> v = truth(series, &to_body);
  return {zero_error(series, v, windows.train), zero_error(series, v, windows.validate), {}, ""};
}

std::optional<VelocityScores> score_velocity(const ImuSeries& series, const ModelParams& params, const Windows& windows,
                                             bool validation_on_other_flights) {
  if (!series.reference) return std::nullopt;
  try {
    if (validation_on_other_flights) {
      // Flown there as on any flight it was not fitted on: its conditions (wind, biases) left behind, `transferred`.
      const ModelParams elsewhere = on_another_flight(params);
      const VelocityError train = evaluate_velocity(series, params.full, windows.train, config_for(params)).estimator;
      VelocityEvaluation validation =
          evaluate_velocity(series, elsewhere.full, windows.validate, config_for(elsewhere));
      return VelocityScores{train, validation.estimator, std::move(validation.gain_over_zero), ""};
    }
    const TimeWindow both[] = {windows.train, windows.validate};
    std::vector<VelocityEvaluation> e = evaluate_velocity(series, params.full, both, config_for(params));
    return VelocityScores{e[0].estimator, e[1].estimator, std::move(e[1].gain_over_zero), ""};
  } catch (const std::invalid_argument& e) {
    VelocityScores zero = zero_velocity_scores(series, params.full.mounting, windows);
    zero.note = std::string("no velocity from this model (") + e.what() + "); scored as zero velocity";
    return zero;
  }
}

std::optional<FilterLikelihood> filter_log_likelihood(const ImuSeries& series, const ModelParams& params,
                                                      const Windows& windows) {
  DragVelocityEstimator estimator(params.full, config_for(params));
  if (!estimator.has_drag(0) || !estimator.has_drag(1)) return std::nullopt;
  const TimeWindow* both[] = {&windows.train, &windows.validate};
  double sums[2] = {0.0, 0.0};
  std::size_t counts[2] = {0, 0};
  constexpr double kLog2Pi = 1.8378770664093453;
  for (std::size_t k = 0; k < series.size(); ++k) {
    const std::optional<DragVelocityEstimate> e = estimator.update(series.sample(k));
    if (!e) continue;
    for (int w = 0; w < 2; ++w) {
      if (!inside(e->t, *both[w])) continue;
      for (int axis = 0; axis < 2; ++axis) {
        const double s = e->innovation_var[axis], nu = e->innovation[axis];
        sums[w] += -0.5 * (nu * nu / s + std::log(s) + kLog2Pi);
        ++counts[w];
      }
    }
  }
  if (counts[0] == 0 || counts[1] == 0) throw std::invalid_argument("the filter gave no estimate inside a window");
  return FilterLikelihood{sums[0] / static_cast<double>(counts[0]), sums[1] / static_cast<double>(counts[1])};
}

namespace {

// Means over consecutive kAnchorBlockSeconds blocks from the series' first sample: of the accelerometer and the
// reference's body velocity (x, y), with each block's centre time. Blocks with no sample (a gap) are left out.
struct Blocks {
  std::vector<double> t;
  std::vector<Eigen::Vector2d> accel, velocity;
};
Blocks block_means(const ImuSeries& series) {
  if (!series.reference) throw std::invalid_argument("the least-squares anchor needs a reference");
  const std::vector<Eigen::Vector3d> v_body = truth(series);
  Blocks out;
  const double t0 = series.t.empty() ? 0.0 : series.t.front();
  std::size_t k = 0;
  while (k < series.size()) {
    const auto block = std::floor((series.t[k] - t0) / kAnchorBlockSeconds);
    Eigen::Vector2d a = Eigen::Vector2d::Zero(), v = Eigen::Vector2d::Zero();
    double n = 0.0;
    for (; k < series.size() && std::floor((series.t[k] - t0) / kAnchorBlockSeconds) == block; ++k, n += 1.0) {
      a += series.accel[k].head<2>();
      v += v_body[k].head<2>();
    }
    out.t.push_back(t0 + (block + 0.5) * kAnchorBlockSeconds);
    out.accel.push_back(a / n);
    out.velocity.push_back(v / n);
  }
  return out;
}

}  // namespace

LeastSquaresDrag fit_least_squares_drag(const ImuSeries& series, const TimeWindow& train) {
  const Blocks blocks = block_means(series);
  LeastSquaresDrag out;
  for (int axis = 0; axis < 2; ++axis) {
    // a = c0 + c1 v: the normal equations of a straight line.
    double n = 0.0, sv = 0.0, sa = 0.0, svv = 0.0, sva = 0.0;
    for (std::size_t i = 0; i < blocks.t.size(); ++i) {
      if (!inside(blocks.t[i], train)) continue;
      const double v = blocks.velocity[i][axis], a = blocks.accel[i][axis];
      n += 1.0, sv += v, sa += a, svv += v * v, sva += v * a;
    }
    if (n == 0.0) throw std::invalid_argument("the least-squares anchor: no 0.1-s block inside the training window");
    const double det = n * svv - sv * sv;
    if (!(det > 0.0) || n < 2.0)
      throw std::invalid_argument("the least-squares anchor: the training velocity does not vary");
    const double slope = (n * sva - sv * sa) / det, intercept = (sa - slope * sv) / n;
    // The slope's standard error from the line's residual (blocks taken as independent).
    double rss = 0.0;
    for (std::size_t i = 0; i < blocks.t.size(); ++i) {
      if (!inside(blocks.t[i], train)) continue;
      const double r = blocks.accel[i][axis] - intercept - slope * blocks.velocity[i][axis];
      rss += r * r;
    }
    const double slope_se = n > 2.0 ? std::sqrt(rss / (n - 2.0) * n / det) : std::numeric_limits<double>::infinity();
    const char* name = axis == 0 ? "x" : "y";
    char what[200];
    if (slope > kAnchorSlopeSignificance * slope_se) {
      std::snprintf(what, sizeof what,
                    "the least-squares anchor: the accelerometer rises with the %s velocity on the training window "
                    "(slope %+.3g ± %.2g 1/s): no drag to invert",
                    name, slope, slope_se);
      throw std::invalid_argument(what);
    }
    if (-slope < kAnchorSlopeSignificance * slope_se) {
      std::snprintf(what, sizeof what, "%sno drag read on %s (slope %+.3g ± %.2g 1/s): zero velocity there",
                    out.note.empty() ? "" : "; ", name, slope, slope_se);
      out.note += what;
      out.b[axis] = sa / n;
      continue;
    }
    out.k[axis] = -slope;
    out.b[axis] = intercept;
  }
  return out;
}

LeastSquaresDragScores score_least_squares_drag(const ImuSeries& series, const LeastSquaresDrag& fit,
                                                const TimeWindow& window) {
  const Blocks blocks = block_means(series);
  std::vector<Eigen::Vector2d> inverted(blocks.t.size());
  for (std::size_t i = 0; i < blocks.t.size(); ++i) {
    for (int axis = 0; axis < 2; ++axis)  // an axis without a drag read flies at zero velocity
      inverted[i][axis] = fit.k[axis] > 0.0 ? (fit.b[axis] - blocks.accel[i][axis]) / fit.k[axis] : 0.0;
  }
  // The centred moving average over the blocks within half the smoothing span (fewer at the ends and at gaps).
  const double half = 0.5 * kAnchorSmoothingSeconds;
  LeastSquaresDragScores out;
  VelocityErrorSum raw, smoothed;
  std::size_t first = 0;
  for (std::size_t i = 0; i < blocks.t.size(); ++i) {
    while (blocks.t[first] < blocks.t[i] - half) ++first;
    if (!inside(blocks.t[i], window)) continue;
    Eigen::Vector2d sum = Eigen::Vector2d::Zero();
    double n = 0.0;
    for (std::size_t j = first; j < blocks.t.size() && blocks.t[j] <= blocks.t[i] + half; ++j, n += 1.0)
      sum += inverted[j];
    raw.add(inverted[i] - blocks.velocity[i]);
    smoothed.add(sum / n - blocks.velocity[i]);
    ++out.blocks;
  }
  if (out.blocks == 0) throw std::invalid_argument("the least-squares anchor: no 0.1-s block inside the window");
  out.raw = raw.rmse();
  out.smoothed = smoothed.rmse();
  return out;
}

TransferOffset measure_transfer_offset(std::span<const ImuSeries> flights, std::span<const TimeWindow> windows,
                                       const ModelParams& params) {
  if (flights.empty() || flights.size() != windows.size())
    throw std::invalid_argument("measuring the transferred offset needs flights, each with its window");
  TransferOffset out;
  // Each flight as a new one: the calibration's conditions stay behind.
  const ModelParams flown = on_another_flight(params);
  const auto nees = [&](double offset_std) {
    double sum = 0.0;
    std::size_t samples = 0;
    for (std::size_t i = 0; i < flights.size(); ++i) {
      DragVelocityConfig config = config_for(flown);
      config.accel_offset_std = offset_std;
      config.wind_std = 0.0;  // the std measured here is the whole of what a new flight carries, its wind included
      const VelocityEvaluation e = evaluate_velocity(flights[i], flown.full, windows[i], config);
      sum += e.nees * static_cast<double>(e.samples);
      samples += e.samples;
    }
    out.samples = samples;
    return sum / static_cast<double>(std::max<std::size_t>(samples, 1));
  };
  constexpr double kHonest = 2.0;  // two axes
  out.flights = flights.size();
  out.nees_default = nees(kTransferredOffsetStd);
  // Each end of the bracket is one run over the flights, kept: no offset, and the largest.
  if (const double without = nees(0.0); without <= kHonest) return out.nees = without, out;
  if (const double largest = nees(kMaxTransferOffsetStd); largest > kHonest) {
    out.offset_std = kMaxTransferOffsetStd, out.at_limit = true;
    out.nees = largest;
    return out;
  }
  // NEES falls as the std grows: bisect in log space, 1e-3 .. kMaxTransferOffsetStd m/s^2, to 1 %.
  double low = std::log(1e-3), high = std::log(kMaxTransferOffsetStd);
  while (high - low > 0.01) {
    const double mid = 0.5 * (low + high);
    (nees(std::exp(mid)) > kHonest ? low : high) = mid;
  }
  out.offset_std = std::exp(high);
  out.nees = nees(out.offset_std);
  return out;
}

}  // namespace imubridge::estimator
