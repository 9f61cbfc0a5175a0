#include "estimator/drag_velocity.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <vector>

#include "estimator/constants.hpp"
#include "estimator/drag_law.hpp"

namespace imubridge::estimator {
namespace {

using std::cos;
using std::sin;

// ---- The drag law and its inverse ----

TEST(DragLaw, InversionRecoversTheVelocityExactly) {
  for (const auto& [k, mu] : {std::pair{0.3, 0.0}, {0.0, 0.04}, {0.3, 0.04}, {1e-4, 2.0}}) {
    for (double v = -15.0; v <= 15.0; v += 0.125) {
      EXPECT_NEAR(invert_drag(k, mu, drag_specific_force(k, mu, v)), v, 1e-12 * (1.0 + std::abs(v))) << k << " " << mu;
    }
  }
}

TEST(DragLaw, ClosedFormsOfThePureLaws) {
  EXPECT_DOUBLE_EQ(invert_drag(0.5, 0.0, -1.5), 3.0);               // linear: v = -f / k
  EXPECT_DOUBLE_EQ(invert_drag(0.0, 0.04, -1.0), std::sqrt(25.0));  // quadratic: v = sqrt(|f| / mu), against f
  EXPECT_DOUBLE_EQ(invert_drag(0.0, 0.04, 1.0), -5.0);
  EXPECT_EQ(invert_drag(0.0, 0.04, 0.0), 0.0);  // the formula's 0/0
  EXPECT_TRUE(std::isnan(invert_drag(0.0, 0.0, 1.0)));
  EXPECT_TRUE(std::isnan(invert_drag(0.0, 0.0, 0.0)));
}

TEST(DragLaw, OpposesMotionMonotonicallyWithTheDocumentedSlope) {
  const double k = 0.3, mu = 0.04, h = 1e-6;
  double previous = drag_specific_force(k, mu, -10.0);
  for (double v = -9.9; v <= 10.0; v += 0.1) {
    const double f = drag_specific_force(k, mu, v);
    EXPECT_LT(f, previous);
    EXPECT_EQ(f<0.0, v> 0.0);
    previous = f;
    const double numeric = (drag_specific_force(k, mu, v - h) - drag_specific_force(k, mu, v + h)) / (2 * h);
    EXPECT_NEAR(drag_slope(k, mu, v), numeric, 1e-6);
  }
}

// ---- A synthetic flight with known velocity ----

// ZYX Euler angles as smooth functions of time; the quadrotor holds its altitude, so its velocity is horizontal.
struct Angles {
  double roll, pitch, yaw;
};
Angles angles(double t) {
  return {0.12 * sin(0.37 * t + 1.0) + 0.04 * sin(2.3 * t), 0.15 * sin(0.5 * t) + 0.05 * sin(1.9 * t),
          0.3 * t + 0.2 * sin(0.8 * t)};
}
Angles angle_rates(double t) {
  return {0.12 * 0.37 * cos(0.37 * t + 1.0) + 0.04 * 2.3 * cos(2.3 * t),
          0.15 * 0.5 * cos(0.5 * t) + 0.05 * 1.9 * cos(1.9 * t), 0.3 + 0.2 * 0.8 * cos(0.8 * t)};
}
Eigen::Matrix3d attitude(double t) {
  const Angles a = angles(t);
  return (Eigen::AngleAxisd(a.yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(a.pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(a.roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}
// Body rates from the Euler-angle rates (the standard ZYX kinematics).
Eigen::Vector3d body_rate(double t) {
  const Angles a = angles(t);
  const Angles d = angle_rates(t);
  return {d.roll - d.yaw * sin(a.pitch), d.pitch * cos(a.roll) + d.yaw * sin(a.roll) * cos(a.pitch),
          -d.pitch * sin(a.roll) + d.yaw * cos(a.roll) * cos(a.pitch)};
}
Eigen::Vector3d body_rate_dot(double t) {
  const double e = 1e-4;
  return (body_rate(t - 2 * e) - 8 * body_rate(t - e) + 8 * body_rate(t + e) - body_rate(t + 2 * e)) / (12 * e);
}

FullModelParams flight_params() {
  FullModelParams p;
  p.lever_arm = {0.12, -0.04, -0.06};
  p.mounting = {0.01, -0.02, 0.05};
  p.drag_linear = {0.35, 0.4};
  p.drag_quadratic = {0.04, 0.05};
  p.accel_bias = {0.05, -0.03, 0.1};
  return p;
}

struct Flight {
  std::vector<ImuSample> samples;
  std::vector<Eigen::Vector2d> body_velocity;  // truth, per sample
  Eigen::Vector2d gyro_bias_body;              // truth, body x, y
};

constexpr double kH = 0.005;        // 200 Hz
constexpr double kAccelStd = 0.1;   // m/s^2 per sample
constexpr double kGyroStd = 0.005;  // rad/s per sample

Flight fly(double duration, unsigned seed) {
  const FullModelParams p = flight_params();
  const Eigen::Matrix3d imu_to_body = Eigen::AngleAxisd(p.mounting.norm(), p.mounting.normalized()).toRotationMatrix();
  const Eigen::Vector3d gyro_bias_imu(0.01, -0.008, 0.0);

  // Mass-centre specific force: drag from the body velocity, and the thrust that holds the altitude.
  const auto specific_force = [&p](double t, const Eigen::Vector3d& v_ned) {
    const Eigen::Matrix3d r = attitude(t);
    const Eigen::Vector3d v = r.transpose() * v_ned;
    const double dx = drag_specific_force(p.drag_linear.x(), p.drag_quadratic.x(), v.x());
    const double dy = drag_specific_force(p.drag_linear.y(), p.drag_quadratic.y(), v.y());
    const double thrust = (kGravity + r(2, 0) * dx + r(2, 1) * dy) / r(2, 2);
    return Eigen::Vector3d(dx, dy, -thrust);
  };
  const auto accel_ned = [&](double t, const Eigen::Vector3d& v_ned) -> Eigen::Vector3d {
    return attitude(t) * specific_force(t, v_ned) + Eigen::Vector3d(0, 0, kGravity);
  };

  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  const auto noise = [&](double std) -> Eigen::Vector3d {
    return Eigen::Vector3d(normal(rng), normal(rng), normal(rng)) * std;
  };

  Flight flight;
  flight.gyro_bias_body = (imu_to_body * gyro_bias_imu).head<2>();
  Eigen::Vector3d v_ned = Eigen::Vector3d::Zero();
  for (int k = 0; k * kH < duration; ++k) {
    const double t = k * kH;
    if (k > 0) {  // RK4 over the last sample period
      const double t0 = t - kH;
      const Eigen::Vector3d a1 = accel_ned(t0, v_ned);
      const Eigen::Vector3d a2 = accel_ned(t0 + kH / 2, v_ned + kH / 2 * a1);
      const Eigen::Vector3d a3 = accel_ned(t0 + kH / 2, v_ned + kH / 2 * a2);
      const Eigen::Vector3d a4 = accel_ned(t, v_ned + kH * a3);
      v_ned += kH / 6 * (a1 + 2 * a2 + 2 * a3 + a4);
    }
    const Eigen::Vector3d v_body = attitude(t).transpose() * v_ned;
    const Eigen::Vector3d f_cm = specific_force(t, v_ned);
    const FullModelInput in{.gyro = imu_to_body.transpose() * body_rate(t),
                            .gyro_rate = imu_to_body.transpose() * body_rate_dot(t),
                            .velocity = v_body.head<2>(),
                            .thrust = -f_cm.z()};
    flight.samples.push_back(
        {t, in.gyro + gyro_bias_imu + noise(kGyroStd), predict_specific_force(p, in) + noise(kAccelStd)});
    flight.body_velocity.push_back(v_body.head<2>());
  }
  return flight;
}

DragVelocityConfig flight_config() {
  DragVelocityConfig c;
  // The compensated force's noise: the accelerometer's plus the lever arm times the differentiated gyro noise,
  // whose std is kGyroStd / (h sqrt(sum u^2)) for the least-squares slope (sum u^2 = 10 for N = 5).
  const double gyro_rate_std = kGyroStd / (kH * std::sqrt(10.0));
  c.accel_noise = std::hypot(kAccelStd, flight_params().lever_arm.norm() * gyro_rate_std);
  c.gyro_noise = kGyroStd * std::sqrt(kH);  // per-sample std -> density
  return c;
}

struct Estimates {
  std::vector<DragVelocityEstimate> estimates;
  std::vector<std::size_t> index;  // the sample each estimate describes
};

Estimates run(DragVelocityEstimator& estimator, const std::vector<ImuSample>& samples) {
  Estimates out;
  for (std::size_t k = 0; k < samples.size(); ++k) {
    if (auto e = estimator.update(samples[k])) {
      out.estimates.push_back(*e);
      out.index.push_back(k - estimator.delay_samples());
    }
  }
  return out;
}

struct ErrorStats {
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  Eigen::Vector2d rms = Eigen::Vector2d::Zero();
  Eigen::Vector2d reported_std = Eigen::Vector2d::Zero();  // sqrt of the mean reported v_var
  double within_two_sigma = 0.0;                           // fraction of filtered errors inside 2 sqrt(v_var)
};

ErrorStats errors(const Estimates& r, const Flight& f, double from, double to, bool raw) {
  ErrorStats s;
  int n = 0;
  for (std::size_t i = 0; i < r.estimates.size(); ++i) {
    const DragVelocityEstimate& e = r.estimates[i];
    if (e.t < from || e.t >= to) continue;
    const Eigen::Vector2d error = (raw ? e.v_raw : e.v) - f.body_velocity[r.index[i]];
    s.mean += error;
    s.rms += error.cwiseAbs2();
    s.reported_std += e.v_var;
    s.within_two_sigma += (error.cwiseAbs2().array() <= 4.0 * e.v_var.array()).cast<double>().sum() / 2.0;
    ++n;
  }
  s.mean /= n;
  s.rms = (s.rms / n).cwiseSqrt();
  s.reported_std = (s.reported_std / n).cwiseSqrt();
  s.within_two_sigma /= n;
  return s;
}

TEST(DragVelocityEstimator, BeatsTheRawInversionAndStaysUnbiasedWithABiasedGyro) {
  const Flight flight = fly(90.0, 11);
  DragVelocityEstimator estimator(flight_params(), flight_config());
  const Estimates r = run(estimator, flight.samples);
  ASSERT_EQ(r.estimates.size(), flight.samples.size() - 4);
  for (std::size_t i = 0; i < r.estimates.size(); ++i) ASSERT_EQ(r.estimates[i].t, flight.samples[r.index[i]].t);

  const ErrorStats raw = errors(r, flight, 10.0, 90.0, true);
  const ErrorStats kf = errors(r, flight, 10.0, 90.0, false);
  Eigen::Vector2d speed_rms = Eigen::Vector2d::Zero();
  for (const auto& v : flight.body_velocity) speed_rms += v.cwiseAbs2();
  speed_rms = (speed_rms / flight.body_velocity.size()).cwiseSqrt();
  for (int axis = 0; axis < 2; ++axis) {
    SCOPED_TRACE(axis);
    EXPECT_GT(speed_rms[axis], 1.0);                         // the flight moves ...
    EXPECT_LT(kf.rms[axis], 0.35 * raw.rms[axis]);           // ... the filter cuts the raw error threefold ...
    EXPECT_LT(std::abs(kf.mean[axis]), 0.2 * kf.rms[axis]);  // ... without a bias (a 0.5 deg tilt error is 0.14 m/s)
    // ... and reports an honest variance: neither overconfident nor uselessly wide.
    EXPECT_GT(kf.reported_std[axis], 0.8 * kf.rms[axis]);
    EXPECT_LT(kf.reported_std[axis], 2.0 * kf.rms[axis]);
  }
  EXPECT_GT(kf.within_two_sigma, 0.9);  // a Gaussian has 95 % inside two sigma
  // It does not drift, although the gyro bias alone would tilt the integrated attitude by ~0.8 rad: it finds it.
  const ErrorStats early = errors(r, flight, 10.0, 40.0, false);
  const ErrorStats late = errors(r, flight, 60.0, 90.0, false);
  EXPECT_LT(late.rms.maxCoeff(), 1.5 * early.rms.maxCoeff());
  EXPECT_LT((r.estimates.back().gyro_bias - flight.gyro_bias_body).norm(), 0.1 * flight.gyro_bias_body.norm());
}

TEST(DragVelocityEstimator, CompensatedForceIsTheDrag) {
  const Flight flight = fly(10.0, 12);
  const FullModelParams p = flight_params();
  DragVelocityEstimator estimator(p, flight_config());
  const Estimates r = run(estimator, flight.samples);
  double sum = 0.0;
  for (std::size_t i = 0; i < r.estimates.size(); ++i) {
    const Eigen::Vector2d& v = flight.body_velocity[r.index[i]];
    const Eigen::Vector2d drag(drag_specific_force(p.drag_linear.x(), p.drag_quadratic.x(), v.x()),
                               drag_specific_force(p.drag_linear.y(), p.drag_quadratic.y(), v.y()));
    sum += (r.estimates[i].f - drag).squaredNorm();
  }
  // Only noise remains: the accelerometer's and the differentiated gyro's (accel_noise), plus the differentiator's
  // small truncation error.
  const double rms = std::sqrt(sum / (2.0 * r.estimates.size()));
  EXPECT_NEAR(rms, flight_config().accel_noise, 0.1 * flight_config().accel_noise);
}

TEST(DragVelocityEstimator, IsBitIdenticalForTheSameInput) {
  const Flight flight = fly(5.0, 13);
  DragVelocityEstimator a(flight_params(), flight_config());
  DragVelocityEstimator b(flight_params(), flight_config());
  const Estimates ra = run(a, flight.samples);
  const Estimates rb = run(b, flight.samples);
  ASSERT_EQ(ra.estimates.size(), rb.estimates.size());
  for (std::size_t i = 0; i < ra.estimates.size(); ++i) {
    EXPECT_EQ(ra.estimates[i].v, rb.estimates[i].v);
    EXPECT_EQ(ra.estimates[i].v_var, rb.estimates[i].v_var);
    EXPECT_EQ(ra.estimates[i].f, rb.estimates[i].f);
  }
}

TEST(DragVelocityEstimator, RejectedSamplesAreCountedAndChangeNothing) {
  const Flight flight = fly(3.0, 14);
  std::vector<ImuSample> dirty;
  for (std::size_t k = 0; k < flight.samples.size(); ++k) {
    dirty.push_back(flight.samples[k]);
    if (k == 100) dirty.push_back({flight.samples[k].t + 0.001, {std::nan(""), 0, 0}, {0, 0, 0}});
    if (k == 200) dirty.push_back({flight.samples[k].t, {0, 0, 0}, {0, 0, 0}});        // repeated time
    if (k == 300) dirty.push_back({flight.samples[k].t - 1.0, {0, 0, 0}, {0, 0, 0}});  // back in time
    if (k == 400) dirty.push_back({flight.samples[k].t + 0.001, {0, 0, 0}, {0, 0, INFINITY}});
    if (k == 500) dirty.push_back({flight.samples[k].t + 0.001, {0, 0, 0}, {1e300, 0, 0}});  // corrupt but finite
    if (k == 550) dirty.push_back({flight.samples[k].t + 0.001, {0, -100.0, 0}, {0, 0, 0}});
  }
  DragVelocityEstimator clean(flight_params(), flight_config());
  DragVelocityEstimator tested(flight_params(), flight_config());
  const Estimates expected = run(clean, flight.samples);
  std::vector<DragVelocityEstimate> got;
  for (const ImuSample& s : dirty) {
    if (auto e = tested.update(s)) got.push_back(*e);
  }
  ASSERT_EQ(got.size(), expected.estimates.size());
  for (std::size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].t, expected.estimates[i].t);
    EXPECT_EQ(got[i].v, expected.estimates[i].v);
  }
  const DragVelocityCounters& c = tested.counters();
  EXPECT_EQ(c.samples_in, dirty.size());
  EXPECT_EQ(c.rejected_non_finite, 2u);
  EXPECT_EQ(c.rejected_time, 2u);
  EXPECT_EQ(c.rejected_out_of_range, 2u);
  EXPECT_EQ(c.estimates_out, got.size());
  EXPECT_EQ(c.gaps, 0u);
}

TEST(DragVelocityEstimator, RestartsTheDifferentiatorAfterAGapAndCarriesOn) {
  const Flight flight = fly(30.0, 15);
  const DragVelocityConfig config = flight_config();
  std::vector<ImuSample> gappy;
  const std::size_t gap_begin = 4000, gap_end = 4050;  // 0.25 s missing, longer than max_gap
  for (std::size_t k = 0; k < flight.samples.size(); ++k) {
    if (k < gap_begin || k >= gap_end) gappy.push_back(flight.samples[k]);
  }
  DragVelocityEstimator estimator(flight_params(), config);
  std::size_t silent_after_gap = 0;
  std::optional<DragVelocityEstimate> first_after_gap;
  for (std::size_t k = 0; k < gappy.size(); ++k) {
    const auto e = estimator.update(gappy[k]);
    if (k >= gap_begin && !first_after_gap) {
      if (e)
        first_after_gap = e;
      else
        ++silent_after_gap;
    }
  }
  EXPECT_EQ(estimator.counters().gaps, 1u);
  EXPECT_EQ(silent_after_gap, 4u);  // the window refills
  ASSERT_TRUE(first_after_gap);
  const std::size_t truth_index = gap_end + estimator.delay_samples();
  EXPECT_EQ(first_after_gap->t, flight.samples[truth_index].t);
  const Eigen::Vector2d error = first_after_gap->v - flight.body_velocity[truth_index];
  for (int axis = 0; axis < 2; ++axis) EXPECT_LT(std::abs(error[axis]), 3.0 * std::sqrt(first_after_gap->v_var[axis]));
}

TEST(DragVelocityEstimator, WithoutDragOnAnAxisCompensatesButReportsNoVelocity) {
  const Flight flight = fly(5.0, 14);
  FullModelParams p = flight_params();
  p.drag_linear.y() = 0.0;  // y not identified yet
  p.drag_quadratic.y() = 0.0;
  DragVelocityEstimator partial(p, flight_config());
  DragVelocityEstimator full(flight_params(), flight_config());
  const Estimates rp = run(partial, flight.samples);
  const Estimates rf = run(full, flight.samples);
  ASSERT_EQ(rp.estimates.size(), rf.estimates.size());
  ASSERT_FALSE(rp.estimates.empty());
  for (std::size_t i = 0; i < rp.estimates.size(); ++i) {
    EXPECT_EQ(rp.estimates[i].f, rf.estimates[i].f);  // compensation does not depend on drag
    EXPECT_TRUE(std::isnan(rp.estimates[i].v.y()));
    EXPECT_TRUE(std::isnan(rp.estimates[i].v_raw.y()));
    EXPECT_TRUE(std::isfinite(rp.estimates[i].v.x()));
  }
  DragVelocityEstimator none(FullModelParams{}, flight_config());  // the defaults: nothing identified at all
  const Estimates rn = run(none, flight.samples);
  ASSERT_EQ(rn.estimates.size(), rf.estimates.size());
  EXPECT_TRUE(rn.estimates.back().v.array().isNaN().all());
}

TEST(DragVelocityEstimator, RefusesBadParamsAndConfigs) {
  FullModelParams p = flight_params();
  p.drag_linear.x() = -0.1;
  EXPECT_THROW(DragVelocityEstimator(p, DragVelocityConfig{}), std::invalid_argument);
  DragVelocityConfig c;
  c.differentiator_window = 4;
  EXPECT_THROW(DragVelocityEstimator(flight_params(), c), std::invalid_argument);
  c = DragVelocityConfig{};
  c.accel_noise = 0.0;
  EXPECT_THROW(DragVelocityEstimator(flight_params(), c), std::invalid_argument);
  c = DragVelocityConfig{};
  c.max_rate = std::nan("");
  EXPECT_THROW(DragVelocityEstimator(flight_params(), c), std::invalid_argument);
  // Pure quadratic drag (the paper's) is accepted: the filter skips the uninformative zero-slope point.
  p = flight_params();
  p.drag_linear.setZero();
  EXPECT_NO_THROW(DragVelocityEstimator(p, DragVelocityConfig{}));
}

}  // namespace
}  // namespace imubridge::estimator
