#include "estimator/drag_velocity.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <random>
#include <vector>

#include "estimator/constants.hpp"
#include "estimator/drag_law.hpp"
#include "identification/identify.hpp"

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
// `wobble` adds a 3-Hz roll and pitch swing of that amplitude (rad): an agile flight's angular acceleration.
struct Angles {
  double roll, pitch, yaw;
};
constexpr double kWobbleRate = 2.0 * kPi * 3.0;  // rad/s
Angles angles(double t, double wobble = 0.0) {
  return {0.12 * sin(0.37 * t + 1.0) + 0.04 * sin(2.3 * t) + wobble * sin(kWobbleRate * t),
          0.15 * sin(0.5 * t) + 0.05 * sin(1.9 * t) + wobble * cos(kWobbleRate * t), 0.3 * t + 0.2 * sin(0.8 * t)};
}
Angles angle_rates(double t, double wobble = 0.0) {
  return {0.12 * 0.37 * cos(0.37 * t + 1.0) + 0.04 * 2.3 * cos(2.3 * t) + wobble * kWobbleRate * cos(kWobbleRate * t),
          0.15 * 0.5 * cos(0.5 * t) + 0.05 * 1.9 * cos(1.9 * t) - wobble * kWobbleRate * sin(kWobbleRate * t),
          0.3 + 0.2 * 0.8 * cos(0.8 * t)};
}
Eigen::Matrix3d attitude(double t, double wobble = 0.0) {
  const Angles a = angles(t, wobble);
  return (Eigen::AngleAxisd(a.yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(a.pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(a.roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}
// Body rates from the Euler-angle rates (the standard ZYX kinematics).
Eigen::Vector3d body_rate(double t, double wobble = 0.0) {
  const Angles a = angles(t, wobble);
  const Angles d = angle_rates(t, wobble);
  return {d.roll - d.yaw * sin(a.pitch), d.pitch * cos(a.roll) + d.yaw * sin(a.roll) * cos(a.pitch),
          -d.pitch * sin(a.roll) + d.yaw * cos(a.roll) * cos(a.pitch)};
}
Eigen::Vector3d body_rate_dot(double t, double wobble = 0.0) {
  const double e = 1e-4;
  return (body_rate(t - 2 * e, wobble) - 8 * body_rate(t - e, wobble) + 8 * body_rate(t + e, wobble) -
          body_rate(t + 2 * e, wobble)) /
         (12 * e);
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
  std::vector<Eigen::Vector3d> velocity_ned;   // truth, per sample
  Eigen::Vector2d gyro_bias_body;              // truth, body x, y
};

constexpr double kH = 0.005;        // 200 Hz
constexpr double kAccelStd = 0.1;   // m/s^2 per sample
constexpr double kGyroStd = 0.005;  // rad/s per sample

// What a flight adds to flight_params()'s sensor and air: the effects beyond the rigid body (the truth's
// accel_scale, accel_cross, gyro_bias, time_offset and wind) and the swing that makes a time offset matter.
struct FlightOptions {
  FullModelParams params = flight_params();
  double wobble = 0.0;
};

Flight fly(double duration, unsigned seed, const FlightOptions& options = {}) {
  const FullModelParams& p = options.params;
  const double wobble = options.wobble;
  const Eigen::Matrix3d imu_to_body = Eigen::AngleAxisd(p.mounting.norm(), p.mounting.normalized()).toRotationMatrix();
  // The gyro bias the filter's own states track, plus the truth's (the gyro_bias effect).
  const Eigen::Vector3d gyro_bias_imu = Eigen::Vector3d(0.01, -0.008, 0.0) + p.gyro_bias;
  const Eigen::Vector3d wind(p.wind.x(), p.wind.y(), 0.0);  // the flight starts at yaw 0: wind_heading 0
  const Eigen::Matrix3d sensor =
      Eigen::Matrix3d::Identity() + Eigen::Matrix3d(p.accel_scale.asDiagonal()) + p.accel_cross;
  const auto lag = static_cast<int>(std::lround(p.time_offset / kH));  // the accelerometer's delay, in samples
  EXPECT_NEAR(lag * kH, p.time_offset, 1e-12);

  // Mass-centre specific force: drag from the body air velocity, and the thrust that holds the altitude.
  const auto specific_force = [&](double t, const Eigen::Vector3d& v_ned) {
    const Eigen::Matrix3d r = attitude(t, wobble);
    const Eigen::Vector3d v = r.transpose() * (v_ned - wind);
    const double dx = drag_specific_force(p.drag_linear.x(), p.drag_quadratic.x(), v.x());
    const double dy = drag_specific_force(p.drag_linear.y(), p.drag_quadratic.y(), v.y());
    const double thrust = (kGravity + r(2, 0) * dx + r(2, 1) * dy) / r(2, 2);
    return Eigen::Vector3d(dx, dy, -thrust);
  };
  const auto accel_ned = [&](double t, const Eigen::Vector3d& v_ned) -> Eigen::Vector3d {
    return attitude(t, wobble) * specific_force(t, v_ned) + Eigen::Vector3d(0, 0, kGravity);
  };

  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  const auto noise = [&](double std) -> Eigen::Vector3d {
    return Eigen::Vector3d(normal(rng), normal(rng), normal(rng)) * std;
  };

  Flight flight;
  flight.gyro_bias_body = (imu_to_body * gyro_bias_imu).head<2>();
  std::vector<Eigen::Vector3d> accel_clean;  // the noiseless readings of each instant
  std::vector<Eigen::Vector3d> gyro_clean;
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
    const Eigen::Matrix3d r = attitude(t, wobble);
    const Eigen::Vector3d v_body = r.transpose() * v_ned;
    const Eigen::Vector3d f_cm = specific_force(t, v_ned);
    const FullModelInput in{.gyro = imu_to_body.transpose() * body_rate(t, wobble),
                            .gyro_rate = imu_to_body.transpose() * body_rate_dot(t, wobble),
                            .velocity = (r.transpose() * (v_ned - wind)).head<2>(),
                            .thrust = -f_cm.z()};
    // m = S f + b_a: predict_specific_force adds the bias to the rigid body's reading.
    accel_clean.push_back(sensor * (predict_specific_force(p, in) - p.accel_bias) + p.accel_bias);
    gyro_clean.push_back(in.gyro + gyro_bias_imu);
    flight.body_velocity.push_back(v_body.head<2>());
    flight.velocity_ned.push_back(v_ned);
  }
  const int n = static_cast<int>(gyro_clean.size());
  for (int k = 0; k < n; ++k) {
    // The accelerometer's sample at t saw the motion of t - time_offset (the flight's ends repeat).
    const Eigen::Vector3d& accel = accel_clean[static_cast<std::size_t>(std::clamp(k - lag, 0, n - 1))];
    const Eigen::Vector3d gyro = gyro_clean[static_cast<std::size_t>(k)] + noise(kGyroStd);
    flight.samples.push_back({k * kH, gyro, accel + noise(kAccelStd)});
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

// The estimate after a minute level and without rotation at 200 Hz, the accelerometer reading `accel` throughout.
DragVelocityEstimate steady_level_estimate(const FullModelParams& params, const DragVelocityConfig& config,
                                           const Eigen::Vector3d& accel) {
  DragVelocityEstimator estimator(params, config);
  std::optional<DragVelocityEstimate> last;
  for (int k = 0; k < 200 * 60; ++k) {
    if (auto e = estimator.update({k / 200.0, Eigen::Vector3d::Zero(), accel})) last = e;
  }
  return *last;
}

TEST(DragVelocityEstimator, WhereTheDragIsTooWeakToReadItRelaxesTowardsRestInsteadOfInventingASpeed) {
  // A vehicle at rest, level, whose accelerometer reads a zero-g offset of 0.3 m/s^2 no fit of this flight placed
  // (a calibration from another flight), with a drag so weak (k = 0.02 1/s) that the offset reads as 15 m/s.
  FullModelParams weak;
  weak.drag_linear = {0.02, 0.02};
  const auto final_estimate = [&](const DragVelocityConfig& config) {
    return steady_level_estimate(weak, config, Eigen::Vector3d(0.3, 0.0, -kGravity));
  };
  DragVelocityConfig blind;  // the offset's share of the error not counted: the mechanism off
  const DragVelocityEstimate invented = final_estimate(blind);
  EXPECT_LT(invented.v.x(), -10.0);  // it flies 10+ m/s backwards, sure of it
  EXPECT_LT(invented.v_var.x(), invented.v.x() * invented.v.x() / 100.0);
  DragVelocityConfig told;
  told.accel_offset_std = kTransferredOffsetStd;
  const DragVelocityEstimate honest = final_estimate(told);
  EXPECT_GT(honest.v.x(), -2.0);                                   // relaxed towards rest ...
  EXPECT_GT(4.0 * honest.v_var.x(), honest.v.x() * honest.v.x());  // ... and its variance covers what is left
  EXPECT_GT(std::sqrt(honest.v_var.x()), 3.0);                     // it says how little it knows
}

TEST(DragVelocityEstimator, AnOffsetReadThroughAQuadraticLawNearRestIsCountedAsTheInverseReadsIt) {
  // A vehicle at rest, level, with the paper's pure quadratic drag, whose accelerometer reads a zero-g offset of one
  // standard deviation (kTransferredOffsetStd) no fit of this flight placed. The law's inverse reads it as
  // sqrt(offset / mu) = 3.8 m/s; the tangent at that speed, offset / (2 mu v), would count half of it, and the
  // variance would claim a 1-sigma error as nearly 2 sigma (normalised error squared 3.5, not about 1).
  FullModelParams quadratic;
  quadratic.drag_quadratic = {0.04, 0.04};
  DragVelocityConfig told;
  told.accel_offset_std = kTransferredOffsetStd;
  const DragVelocityEstimate e =
      steady_level_estimate(quadratic, told, Eigen::Vector3d(kTransferredOffsetStd, 0.0, -kGravity));
  EXPECT_LT(e.v.x(), -1.0);  // the offset still reads as a speed, weighed towards rest
  const double nees = e.v.x() * e.v.x() / e.v_var.x();
  EXPECT_GT(nees, 0.5);
  EXPECT_LT(nees, 2.0);
  // A linear law's inverse is its tangent: the same weighing as before, offset / k.
  FullModelParams linear;
  linear.drag_linear = {0.3, 0.3};
  const DragVelocityEstimate l =
      steady_level_estimate(linear, told, Eigen::Vector3d(kTransferredOffsetStd, 0.0, -kGravity));
  EXPECT_LT(l.v.x() * l.v.x() / l.v_var.x(), 2.0);
}

TEST(DragVelocityEstimator, OnAnotherFlightTheUnknownWindWeighsTheVelocityTowardsRest) {
  // A steady 4 m/s through the air, read by a strong drag (k = 0.5 1/s: the accelerometer's offset is a small share).
  // Over the ground the vehicle flies 4 m/s plus a wind that a calibration from another flight does not know.
  FullModelParams strong;
  strong.drag_linear = {0.5, 0.5};
  const auto final_estimate = [&](const DragVelocityConfig& config) {
    return steady_level_estimate(strong, config, Eigen::Vector3d(-2.0, 0.0, -kGravity));  // the drag, -k v, on x
  };
  DragVelocityConfig own_flight;  // the model's own flight: its wind is in the fit
  const DragVelocityEstimate own = final_estimate(own_flight);
  DragVelocityConfig another = own_flight;
  another.wind_std = kTransferredWindStd;
  const DragVelocityEstimate flown = final_estimate(another);
  EXPECT_GT(own.v.x(), 3.8);
  const double rest = own_flight.rest_speed_std * own_flight.rest_speed_std;
  const double wind = kTransferredWindStd * kTransferredWindStd;
  // The same filter state x with the same variance p (own.v = x rest / (rest + p), own.v_var = p rest / (rest + p)),
  // weighed against rest with the wind's variance added to p.
  const double p = own.v_var.x() * rest / (rest - own.v_var.x());
  const double x = own.v.x() * (rest + p) / rest;
  EXPECT_NEAR(flown.v.x(), x * rest / (rest + p + wind), 1e-9);
  EXPECT_LT(flown.v.x(), 0.7 * own.v.x());                 // relaxed towards rest ...
  EXPECT_GT(flown.v_var.x(), own.v_var.x() + 0.3 * wind);  // ... and it says the wind is not known
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

// Two estimators with the same parameters over the same samples give the same estimates, bit for bit.
void expect_bit_identical(const FullModelParams& params, const Flight& flight) {
  DragVelocityEstimator a(params, flight_config());
  DragVelocityEstimator b(params, flight_config());
  const Estimates ra = run(a, flight.samples);
  const Estimates rb = run(b, flight.samples);
  ASSERT_EQ(ra.estimates.size(), rb.estimates.size());
  for (std::size_t i = 0; i < ra.estimates.size(); ++i) {
    EXPECT_EQ(ra.estimates[i].v, rb.estimates[i].v);
    EXPECT_EQ(ra.estimates[i].v_var, rb.estimates[i].v_var);
    EXPECT_EQ(ra.estimates[i].f, rb.estimates[i].f);
  }
}

TEST(DragVelocityEstimator, IsBitIdenticalForTheSameInput) { expect_bit_identical(flight_params(), fly(5.0, 13)); }

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

// An axis the model reads no drag on, beside one it does, has nothing to measure its velocity by: it reads rest, as
// sure as the prior and no surer (never a speed), and the compensation is the same. Nothing identified: unknown.
TEST(DragVelocityEstimator, WithoutDragOnAnAxisReadsRestThereAsSureAsThePrior) {
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
    EXPECT_EQ(rp.estimates[i].v.y(), 0.0);
    EXPECT_EQ(rp.estimates[i].v_raw.y(), 0.0);
    const double prior = flight_config().rest_speed_std * flight_config().rest_speed_std;
    EXPECT_EQ(rp.estimates[i].v_var.y(), prior);
    EXPECT_EQ(rp.estimates[i].v_raw_var.y(), prior);
    EXPECT_TRUE(std::isfinite(rp.estimates[i].v.x()));
    EXPECT_LT(rp.estimates[i].v_var.x(), prior);
  }
  DragVelocityEstimator none(FullModelParams{}, flight_config());  // the defaults: nothing identified at all
  const Estimates rn = run(none, flight.samples);
  ASSERT_EQ(rn.estimates.size(), rf.estimates.size());
  EXPECT_TRUE(rn.estimates.back().v.array().isNaN().all());
}

// ---- On the ground (set_landed: the autopilot's land detector) ----

// A vehicle standing still at `stance` (body -> NED) for `duration` s from `t0`, read by flight_params()'s IMU: gravity
// through the stance and the mounting, the accelerometer's bias, and fly()'s gyro bias, with fly()'s noise.
std::vector<ImuSample> stand(const Eigen::Matrix3d& stance, double t0, double duration, unsigned seed) {
  const FullModelParams p = flight_params();
  const Eigen::Matrix3d imu_to_body = Eigen::AngleAxisd(p.mounting.norm(), p.mounting.normalized()).toRotationMatrix();
  const Eigen::Vector3d accel =
      imu_to_body.transpose() * stance.transpose() * Eigen::Vector3d(0, 0, -kGravity) + p.accel_bias;
  const Eigen::Vector3d gyro(0.01, -0.008, 0.0);
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::vector<ImuSample> out;
  for (int k = 0; k * kH < duration; ++k) {
    out.push_back({t0 + k * kH, gyro + kGyroStd * Eigen::Vector3d(normal(rng), normal(rng), normal(rng)),
                   accel + kAccelStd * Eigen::Vector3d(normal(rng), normal(rng), normal(rng))});
  }
  return out;
}

// On its legs, a vehicle's horizontal accelerometers read the stance's tilt, not drag; the drag law reads that as a
// speed. Landed, the filter reads rest, as sure as it is, whatever the tilt.
TEST(DragVelocityEstimator, LandedItReadsRestWhereTheDragLawReadsTheStancesTiltAsASpeed) {
  // Standing 3 degrees rolled on uneven ground: 0.51 m/s^2 of gravity on y, 1.3 m/s through k_y = 0.4 1/s.
  const Eigen::Matrix3d stance = Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const std::vector<ImuSample> samples = stand(stance, 0.0, 30.0, 31);
  DragVelocityEstimator told(flight_params(), flight_config());
  told.set_landed(true);
  EXPECT_TRUE(told.landed());
  DragVelocityEstimator untold(flight_params(), flight_config());
  const Estimates landed = run(told, samples);
  const Estimates flying = run(untold, samples);
  ASSERT_FALSE(landed.estimates.empty());
  EXPECT_EQ(told.counters().landed, landed.estimates.size());
  EXPECT_EQ(untold.counters().landed, 0u);
  EXPECT_GT(std::abs(flying.estimates.back().v.y()), 0.8);  // the mechanism off: a phantom speed
  for (std::size_t i = landed.estimates.size() / 10; i < landed.estimates.size(); ++i) {
    const DragVelocityEstimate& e = landed.estimates[i];
    ASSERT_LT(e.v.cwiseAbs().maxCoeff(), 0.02) << e.t;
    ASSERT_LT(e.v_var.maxCoeff(), 0.05 * 0.05) << e.t;  // no surer than the legs hold it, and far surer than the drag
    ASSERT_GT(e.v_var.minCoeff(), 0.0) << e.t;
  }
}

// Landed until take-off, the flight starts from rest with the tilt levelled on the accelerometer and the gyro bias
// learnt; a filter that read the stance as drag takes off with a phantom speed and a tilt to unlearn.
TEST(DragVelocityEstimator, TakesOffFromRestWhenTheGroundWasFusedAsRest) {
  const Flight flight = fly(20.0, 32);
  const double ground = 20.0;  // s on the ground before the flight, at the flight's first attitude
  std::vector<ImuSample> samples = stand(attitude(0.0), 0.0, ground, 33);
  const std::size_t takeoff = samples.size();
  for (ImuSample s : flight.samples) {
    s.t += ground;
    samples.push_back(s);
  }
  const auto flight_error = [&](bool land_detector) {
    DragVelocityEstimator estimator(flight_params(), flight_config());
    estimator.set_landed(land_detector);
    Eigen::Vector2d sum = Eigen::Vector2d::Zero();
    int n = 0;
    for (std::size_t k = 0; k < samples.size(); ++k) {
      if (k == takeoff) estimator.set_landed(false);
      const auto e = estimator.update(samples[k]);
      const std::size_t described = k - static_cast<std::size_t>(estimator.delay_samples());
      if (!e || described < takeoff || e->t >= ground + 5.0) continue;  // the flight's first 5 s
      sum += (e->v - flight.body_velocity[described - takeoff]).cwiseAbs2();
      ++n;
    }
    return std::sqrt(sum.sum() / n);
  };
  const double from_rest = flight_error(true);
  const double from_phantom = flight_error(false);
  std::printf("first 5 s of flight: velocity RMSE %.3f m/s landed on the ground, %.3f m/s without\n", from_rest,
              from_phantom);
  EXPECT_LT(from_rest, 0.5 * from_phantom);
}

// A crash: 2 s of tumbling at 50 Hz (rates up to 30 rad/s, specific force up to 12 g, as ArduCopter's log171 ends).
// The filter's covariance loses its positive definiteness there and its state turns NaN, for good; it must instead
// notice, start again from level and rest (knowing nothing of the velocity, and saying so), and read the flight after.
TEST(DragVelocityEstimator, AfterACrashThatWreckedItsStateItStartsAgainInsteadOfStayingNaN) {
  const Flight flight = fly(40.0, 34);
  std::mt19937 rng(35);
  std::uniform_real_distribution<double> rate(-30.0, 30.0), force(-12.0 * kGravity, 12.0 * kGravity);
  std::vector<ImuSample> samples(flight.samples.begin(), flight.samples.begin() + 2000);  // 10 s of flight
  const double crash_end = 12.0;
  for (double t = 10.0; t < crash_end; t += 0.02) {
    samples.push_back(
        {t, Eigen::Vector3d(rate(rng), rate(rng), rate(rng)), Eigen::Vector3d(force(rng), force(rng), force(rng))});
  }
  for (std::size_t k = 2400; k < flight.samples.size(); ++k) samples.push_back(flight.samples[k]);  // 12 s on
  DragVelocityEstimator estimator(flight_params(), flight_config());
  Eigen::Vector2d late_error = Eigen::Vector2d::Zero();
  int late = 0;
  for (const ImuSample& s : samples) {
    const auto e = estimator.update(s);
    if (!e) continue;
    ASSERT_TRUE(e->v.allFinite()) << e->t;
    ASSERT_TRUE((e->v_var.array() > 1e-8).all()) << e->t;  // never sure of a velocity it cannot know
    if (e->t >= 30.0) {
      const std::size_t k = static_cast<std::size_t>(std::lround(e->t / kH));
      late_error += (e->v - flight.body_velocity[k]).cwiseAbs2();
      ++late;
    }
  }
  EXPECT_GE(estimator.counters().resets, 1u);
  ASSERT_GT(late, 0);
  std::printf("%llu resets; velocity RMSE from 18 s after the crash %.3f m/s\n",
              static_cast<unsigned long long>(estimator.counters().resets), std::sqrt(late_error.sum() / late));
  EXPECT_LT(std::sqrt(late_error.sum() / late), 0.5);  // 18 s after the crash it reads the flight again
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
  c.landed_speed_std = 0.0;
  EXPECT_THROW(DragVelocityEstimator(flight_params(), c), std::invalid_argument);
  c = DragVelocityConfig{};
  c.max_rate = std::nan("");
  EXPECT_THROW(DragVelocityEstimator(flight_params(), c), std::invalid_argument);
  // Pure quadratic drag (the paper's) is accepted.
  p = flight_params();
  p.drag_linear.setZero();
  EXPECT_NO_THROW(DragVelocityEstimator(p, DragVelocityConfig{}));
}

// ---- The effects beyond the rigid body (docs/effects.md, "Live") ----

// The filter's horizontal velocity error RMS (m/s) against the flight's ground velocity, from 10 s on.
double velocity_rmse(const Flight& flight, const FullModelParams& params, double duration,
                     DragVelocityCounters* counters = nullptr, double from = 10.0) {
  DragVelocityEstimator estimator(params, flight_config());
  const Estimates r = run(estimator, flight.samples);
  EXPECT_FALSE(r.estimates.empty());
  for (std::size_t i = 0; i < r.estimates.size(); ++i) EXPECT_EQ(r.estimates[i].t, flight.samples[r.index[i]].t);
  if (counters) *counters = estimator.counters();
  return errors(r, flight, from, duration, false).rms.norm();
}

// Flies with the truth's effect and estimates twice: given the truth, and given the truth without the effect.
struct EffectRun {
  double with = 0.0;     // m/s
  double without = 0.0;  // m/s
};
EffectRun with_and_without(const FlightOptions& truth, const FullModelParams& without, double duration = 60.0,
                           unsigned seed = 21) {
  const Flight flight = fly(duration, seed, truth);
  EffectRun out{velocity_rmse(flight, truth.params, duration), velocity_rmse(flight, without, duration)};
  std::printf("velocity RMSE with the effect %.4f m/s, without %.4f m/s\n", out.with, out.without);
  return out;
}

TEST(DragVelocityEffects, GyroBiasIsSubtractedFromEveryReading) {
  // The filter's bias states track x and y on their own; the yaw rate's bias they cannot see (it turns v through
  // w_z x v, and the drag measurement pulls it back), so without the parameter the error grows by about 1.7 times,
  // not more: the assertion is that with it the flight is estimated as well as one without any extra bias.
  FlightOptions truth;
  truth.params.gyro_bias = {0.05, -0.04, 0.3};  // rad/s
  const Flight flight = fly(60.0, 21, truth);
  const double with = velocity_rmse(flight, truth.params, 60.0);
  const double without = velocity_rmse(flight, flight_params(), 60.0);
  const double unbiased = velocity_rmse(fly(60.0, 21), flight_params(), 60.0);
  std::printf("velocity RMSE with the gyro bias %.4f m/s, without %.4f m/s, flight without it %.4f m/s\n", with,
              without, unbiased);
  EXPECT_LT(with, 0.7 * without);
  EXPECT_LT(with, 1.05 * unbiased);
  EXPECT_LT(with, 0.12);
  // What is left for the filter's states is the flight's own small bias, not the parameter's.
  DragVelocityEstimator estimator(truth.params, flight_config());
  const Estimates r = run(estimator, flight.samples);
  const Eigen::Vector2d remaining = fly(1.0, 21).gyro_bias_body;
  EXPECT_LT((r.estimates.back().gyro_bias - remaining).norm(), 0.2 * remaining.norm());
}

TEST(DragVelocityEffects, AccelerometerScaleAndCrossAxisErrorsAreUndone) {
  FlightOptions truth;
  truth.params.accel_scale = {0.05, -0.04, 0.03};
  truth.params.accel_cross << 0.0, 0.03, 0.02,  // x reads 2 % of z: 0.2 m/s^2 of thrust on a drag axis
      -0.02, 0.0, -0.015,                       //
      0.01, 0.01, 0.0;
  const EffectRun r = with_and_without(truth, flight_params());
  EXPECT_LT(r.with, 0.5 * r.without);
  EXPECT_LT(r.with, 0.12);
}

TEST(DragVelocityEffects, TimeOffsetPairsTheAccelerometerWithTheGyroOfItsInstant) {
  for (const double tau : {0.02, -0.02}) {
    SCOPED_TRACE(tau);
    FlightOptions truth;
    truth.params.time_offset = tau;
    truth.wobble = 0.05;  // 3 Hz: the lever arm's reading changes within 20 ms
    FlightOptions no_offset = truth;
    no_offset.params.time_offset = 0.0;
    const EffectRun r = with_and_without(truth, no_offset.params);
    EXPECT_LT(r.with, 0.5 * r.without);
    EXPECT_LT(r.with, 0.12);
    // The first 20 ms have no partner 20 ms back: counted, not estimated.
    const Flight flight = fly(12.0, 21, truth);
    DragVelocityCounters c;
    velocity_rmse(flight, truth.params, 12.0, &c);
    EXPECT_GE(c.aligning, 4u);
    EXPECT_LE(c.aligning, 5u);
    EXPECT_EQ(c.estimates_out + c.aligning + 4, flight.samples.size());
  }
}

TEST(DragVelocityEffects, WindMakesTheDragActOnTheAirVelocityAndTheOutputIsTheGroundVelocity) {
  FlightOptions truth;
  truth.params.wind = {3.0, 0.0};  // m/s from the south, in the flight's frame (yaw 0 at its start)
  const Flight flight = fly(60.0, 21, truth);
  const double with = velocity_rmse(flight, truth.params, 60.0);
  const double without = velocity_rmse(flight, flight_params(), 60.0);
  std::printf("velocity RMSE with the wind %.4f m/s, without %.4f m/s\n", with, without);
  EXPECT_LT(with, 0.5 * without);
  EXPECT_LT(with, 0.12);
  // The ground and the air velocity differ by the wind, so a small error against the ground's means the output is
  // the ground velocity.
  double air_minus_ground = 0.0;
  for (std::size_t k = 0; k < flight.samples.size(); ++k) {
    const Eigen::Vector3d wind_body = attitude(flight.samples[k].t).transpose() * Eigen::Vector3d(3.0, 0.0, 0.0);
    air_minus_ground += wind_body.head<2>().squaredNorm();
  }
  EXPECT_GT(std::sqrt(air_minus_ground / flight.samples.size()), 20.0 * with);

  // The same wind written in a world frame in which the flight starts at yaw 1 rad: wind_heading says so.
  FullModelParams turned = truth.params;
  const double psi0 = 1.0;
  turned.wind = Eigen::Rotation2Dd(psi0) * truth.params.wind;
  turned.wind_heading = psi0;
  const double with_turned = velocity_rmse(flight, turned, 60.0);
  turned.wind_heading = 0.0;  // the heading forgotten: the wind blows from the wrong side
  const double heading_forgotten = velocity_rmse(flight, turned, 60.0);
  std::printf("turned frame: with wind_heading %.4f m/s, without %.4f m/s\n", with_turned, heading_forgotten);
  EXPECT_NEAR(with_turned, with, 0.1 * with);
  EXPECT_LT(with_turned, 0.5 * heading_forgotten);
}

TEST(DragVelocityEffects, EveryEffectTogetherIsBitIdenticalForTheSameInput) {
  FlightOptions truth;
  truth.params.gyro_bias = {0.03, -0.04, 0.1};
  truth.params.accel_scale = {0.05, -0.04, 0.03};
  truth.params.accel_cross(0, 2) = 0.02;
  truth.params.time_offset = 0.02;
  truth.params.wind = {2.0, -1.0};
  expect_bit_identical(truth.params, fly(5.0, 22, truth));
}

TEST(DragVelocityEffects, RefusesParametersOutsideTheirRange) {
  FullModelParams p = flight_params();
  p.time_offset = 0.3;
  EXPECT_THROW(DragVelocityEstimator(p, DragVelocityConfig{}), std::invalid_argument);
  p = flight_params();
  p.accel_scale.x() = -1.0;
  EXPECT_THROW(DragVelocityEstimator(p, DragVelocityConfig{}), std::invalid_argument);
  p = flight_params();
  p.accel_cross(1, 1) = 0.01;
  EXPECT_THROW(DragVelocityEstimator(p, DragVelocityConfig{}), std::invalid_argument);
  p = flight_params();
  p.wind.x() = std::nan("");
  EXPECT_THROW(DragVelocityEstimator(p, DragVelocityConfig{}), std::invalid_argument);
}

TEST(VelocityEvaluation, ScoresInTheEstimatorsBodyFrame) {
  // An IMU turned a quarter turn about z: the reference, in the series' (IMU) axes, is turned by R_bs before it is
  // compared with the estimator's body-frame velocity.
  const double duration = 40.0;
  FlightOptions truth;
  truth.params.mounting = {0.01, -0.02, kPi / 2};
  const Flight flight = fly(duration, 23, truth);
  const Eigen::Quaterniond imu_to_body(
      Eigen::AngleAxisd(truth.params.mounting.norm(), truth.params.mounting.normalized()));
  ImuSeries series;
  series.reference.emplace();
  for (std::size_t k = 0; k < flight.samples.size(); ++k) {
    series.t.push_back(flight.samples[k].t);
    series.gyro.push_back(flight.samples[k].gyro);
    series.accel.push_back(flight.samples[k].accel);
    series.reference->velocity_ned.push_back(flight.velocity_ned[k]);
    series.reference->attitude.push_back(Eigen::Quaterniond(attitude(series.t.back())) * imu_to_body);
  }
  const VelocityEvaluation e = evaluate_velocity(series, truth.params, TimeWindow{10.0, duration}, flight_config());
  std::printf("estimator %.4f m/s, standing still %.4f m/s\n", e.estimator.horizontal, e.zero.horizontal);
  EXPECT_LT(e.estimator.horizontal, 0.12);
  EXPECT_LT(e.estimator.horizontal, 0.1 * e.zero.horizontal);
  EXPECT_LT(e.estimator.horizontal, 0.5 * e.inversion.horizontal);
}

}  // namespace
}  // namespace imubridge::estimator
