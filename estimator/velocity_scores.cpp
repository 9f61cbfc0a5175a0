#include "estimator/velocity_scores.hpp"

#include <cmath>
#include <stdexcept>

#include <Eigen/Geometry>

namespace imubridge::estimator {
namespace {

VelocityError zero_error(const ImuSeries& series, const Eigen::Matrix3d& imu_to_body, const TimeWindow& w) {
  double sx = 0.0, sy = 0.0;
  std::size_t n = 0;
  for (std::size_t k = 0; k < series.size(); ++k) {
    if (series.t[k] < w.start || !(series.t[k] < w.end)) continue;
    const Eigen::Vector3d v =
        imu_to_body * (series.reference->attitude[k].conjugate() * series.reference->velocity_ned[k]);
    sx += v.x() * v.x(), sy += v.y() * v.y(), ++n;
  }
  const double count = static_cast<double>(std::max<std::size_t>(n, 1));
  VelocityError out;
  out.axis = {std::sqrt(sx / count), std::sqrt(sy / count)};
  out.horizontal = std::sqrt((sx + sy) / count);
  return out;
}

}  // namespace

VelocityScores zero_velocity_scores(const ImuSeries& series, const Eigen::Vector3d& mounting, const Windows& windows) {
  if (!series.reference) throw std::invalid_argument("zero velocity's error needs a reference");
  const double angle = mounting.norm();
  const Eigen::Matrix3d imu_to_body = angle == 0.0 ? Eigen::Matrix3d::Identity()
                                                   : Eigen::AngleAxisd(angle, mounting / angle).toRotationMatrix();
  return {zero_error(series, imu_to_body, windows.train), zero_error(series, imu_to_body, windows.validate), ""};
}

std::optional<VelocityScores> score_velocity(const ImuSeries& series, const ModelParams& params,
                                             const Windows& windows) {
  if (!series.reference) return std::nullopt;
  try {
    const DragVelocityConfig config = config_for(params);
    return VelocityScores{evaluate_velocity(series, params.full, windows.train, config).estimator,
                          evaluate_velocity(series, params.full, windows.validate, config).estimator, ""};
  } catch (const std::invalid_argument& e) {
    VelocityScores zero = zero_velocity_scores(series, params.full.mounting, windows);
    zero.note = std::string("no velocity from this model (") + e.what() + "); scored as zero velocity";
    return zero;
  }
}

LinearDragBaseline linear_drag_baseline(const ImuSeries& series, const Windows& windows) {
  if (!series.reference) throw std::invalid_argument("the linear least-squares baseline needs a reference");
  const auto body_velocity = [&](std::size_t k) {
    return Eigen::Vector3d(series.reference->attitude[k].conjugate() * series.reference->velocity_ned[k]);
  };
  const auto inside = [&](std::size_t k, const TimeWindow& w) { return series.t[k] >= w.start && series.t[k] < w.end; };
  LinearDragBaseline out;
  for (int axis = 0; axis < 2; ++axis) {
    // a = c0 + c1 v: the normal equations of a straight line.
    double n = 0.0, sv = 0.0, sa = 0.0, svv = 0.0, sva = 0.0;
    for (std::size_t k = 0; k < series.size(); ++k) {
      if (!inside(k, windows.train)) continue;
      const double v = body_velocity(k)[axis], a = series.accel[k][axis];
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
    double sx = 0.0, sy = 0.0, count = 0.0;
    for (std::size_t k = 0; k < series.size(); ++k) {
      if (!inside(k, w)) continue;
      const Eigen::Vector3d truth = body_velocity(k);
      const double ex = (out.b.x() - series.accel[k].x()) / out.k.x() - truth.x();
      const double ey = (out.b.y() - series.accel[k].y()) / out.k.y() - truth.y();
      sx += ex * ex, sy += ey * ey, count += 1.0;
    }
    count = std::max(count, 1.0);
    VelocityError e;
    e.axis = {std::sqrt(sx / count), std::sqrt(sy / count)};
    e.horizontal = std::sqrt((sx + sy) / count);
    return e;
  };
  out.scores = {score(windows.train), score(windows.validate), ""};
  return out;
}

}  // namespace imubridge::estimator
