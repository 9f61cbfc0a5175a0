#include "estimator/velocity_scores.hpp"

#include <cmath>
#include <stdexcept>

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
  return {zero_error(series, v, windows.train), zero_error(series, v, windows.validate), ""};
}

std::optional<VelocityScores> score_velocity(const ImuSeries& series, const ModelParams& params,
                                             const Windows& windows) {
  if (!series.reference) return std::nullopt;
  try {
    const TimeWindow both[] = {windows.train, windows.validate};
    const std::vector<VelocityEvaluation> e = evaluate_velocity(series, params.full, both, config_for(params));
    return VelocityScores{e[0].estimator, e[1].estimator, ""};
  } catch (const std::invalid_argument& e) {
    VelocityScores zero = zero_velocity_scores(series, params.full.mounting, windows);
    zero.note = std::string("no velocity from this model (") + e.what() + "); scored as zero velocity";
    return zero;
  }
}

FilterLikelihood filter_log_likelihood(const ImuSeries& series, const ModelParams& params, const Windows& windows) {
  DragVelocityEstimator estimator(params.full, config_for(params));
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
  return {sums[0] / static_cast<double>(counts[0]), sums[1] / static_cast<double>(counts[1])};
}

LinearDragBaseline linear_drag_baseline(const ImuSeries& series, const Windows& windows) {
  if (!series.reference) throw std::invalid_argument("the linear least-squares baseline needs a reference");
  const std::vector<Eigen::Vector3d> v_body = truth(series);
  LinearDragBaseline out;
  for (int axis = 0; axis < 2; ++axis) {
    // a = c0 + c1 v: the normal equations of a straight line.
    double n = 0.0, sv = 0.0, sa = 0.0, svv = 0.0, sva = 0.0;
    for (std::size_t k = 0; k < series.size(); ++k) {
      if (!inside(series.t[k], windows.train)) continue;
      const double v = v_body[k][axis], a = series.accel[k][axis];
      n += 1.0, sv += v, sa += a, svv += v * v, sva += v * a;
    }
    const double det = n * svv - sv * sv;
    if (!(det > 0.0) || n < 2.0)
      throw std::invalid_argument("the linear least-squares baseline: the training velocity does not vary");
    const double slope = (n * sva - sv * sa) / det;
    out.k[axis] = -slope;
    out.b[axis] = (sa - slope * sv) / n;
  }
  const auto score = [&](const TimeWindow& w) {
    VelocityErrorSum sum;
    for (std::size_t k = 0; k < series.size(); ++k) {
      if (!inside(series.t[k], w)) continue;
      const Eigen::Vector2d v = (out.b - series.accel[k].head<2>()).cwiseQuotient(out.k);
      sum.add(v - v_body[k].head<2>());
    }
    return sum.rmse();
  };
  out.scores = {score(windows.train), score(windows.validate), ""};
  return out;
}

}  // namespace imubridge::estimator
