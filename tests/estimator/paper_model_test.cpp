#include "estimator/paper_model.hpp"

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace imubridge::estimator {
namespace {

using std::cos;
using std::sin;

const PaperAxisParams kPaperFit{.r = 0.179, .beta = 85.12 * kPi / 180.0, .alpha = -0.3 * kPi / 180.0, .mu = 0.0386};

// Rotations about y and x with their first and second derivatives with respect to the angle.
Eigen::Matrix3d rot_y(double a) {
  return (Eigen::Matrix3d() << cos(a), 0, sin(a), 0, 1, 0, -sin(a), 0, cos(a)).finished();
}
Eigen::Matrix3d rot_y_d1(double a) {
  return (Eigen::Matrix3d() << -sin(a), 0, cos(a), 0, 0, 0, -cos(a), 0, -sin(a)).finished();
}
Eigen::Matrix3d rot_y_d2(double a) {
  return (Eigen::Matrix3d() << -cos(a), 0, -sin(a), 0, 0, 0, sin(a), 0, -cos(a)).finished();
}
Eigen::Matrix3d rot_x(double a) {
  return (Eigen::Matrix3d() << 1, 0, 0, 0, cos(a), -sin(a), 0, sin(a), cos(a)).finished();
}
Eigen::Matrix3d rot_x_d1(double a) {
  return (Eigen::Matrix3d() << 0, 0, 0, 0, -sin(a), -cos(a), 0, cos(a), -sin(a)).finished();
}
Eigen::Matrix3d rot_x_d2(double a) {
  return (Eigen::Matrix3d() << 0, 0, 0, 0, -cos(a), sin(a), 0, -sin(a), -cos(a)).finished();
}

// A quadrotor rotating about one body axis, its mass centre's specific force (drag, -g) known. The IMU's
// specific force comes from differentiating its world offset R(angle) p twice, not from the model's cross products.
struct Reading {
  Eigen::Vector3d sensor;  // what the IMU reads, sensor axes
  Eigen::Vector3d lever;   // the lever-arm acceleration, body axes
  double drag;             // the drag specific force along the axis, body axes
};

// Pitch: IMU at r (cos b, 0, -sin b), sensor x axis (cos a, 0, -sin a), i.e. sensor <- body is R_y(a)^T.
Reading pitch_physics(const PaperAxisParams& p, double theta, double rate, double accel, double drag) {
  const Eigen::Vector3d offset = p.r * Eigen::Vector3d(cos(p.beta), 0, -sin(p.beta));
  const Eigen::Vector3d lever =
      rot_y(theta).transpose() * (accel * rot_y_d1(theta) + rate * rate * rot_y_d2(theta)) * offset;
  return {rot_y(p.alpha).transpose() * (Eigen::Vector3d(drag, 0, -kGravity) + lever), lever, drag};
}

// Roll, as docs/estimator.md maps it: IMU at r (0, cos b, -sin b), sensor y axis (0, cos a, -sin a), i.e.
// sensor <- body is R_x(a).
Reading roll_physics(const PaperAxisParams& p, double phi, double rate, double accel, double drag) {
  const Eigen::Vector3d offset = p.r * Eigen::Vector3d(0, cos(p.beta), -sin(p.beta));
  const Eigen::Vector3d lever = rot_x(phi).transpose() * (accel * rot_x_d1(phi) + rate * rate * rot_x_d2(phi)) * offset;
  return {rot_x(p.alpha) * (Eigen::Vector3d(0, drag, -kGravity) + lever), lever, drag};
}

// A manoeuvre: angle(t) = sum of two sines, with its exact rate and acceleration; a horizontal NED velocity profile.
struct Manoeuvre {
  double angle(double t) const { return 0.25 * sin(3.1 * t) + 0.08 * sin(10.7 * t); }
  double rate(double t) const { return 0.25 * 3.1 * cos(3.1 * t) + 0.08 * 10.7 * cos(10.7 * t); }
  double accel(double t) const { return -0.25 * 3.1 * 3.1 * sin(3.1 * t) - 0.08 * 10.7 * 10.7 * sin(10.7 * t); }
  double velocity_ned(double t) const { return 3.0 * sin(0.4 * t) + 0.5; }
};

// docs/model.md: drag opposes the NED velocity V, f = -mu |V| V, and the paper's v is -V.
double drag_of(double mu, double v_ned) { return -mu * std::abs(v_ned) * v_ned; }

double eq14(const PaperAxisParams& p, double omega, double omega_dot, double v_paper) {
  return paper_specific_force(paper_coefficients(p), PaperSample{.omega = omega, .omega_dot = omega_dot, .v = v_paper});
}

TEST(PaperModel, ReproducesPitchPhysicsExactlyWithAnAlignedSensor) {
  PaperAxisParams p = kPaperFit;
  p.alpha = 0.0;
  const Manoeuvre m;
  for (double t = 0.0; t < 5.0; t += 0.01) {
    const double v = m.velocity_ned(t);
    const Reading truth = pitch_physics(p, m.angle(t), m.rate(t), m.accel(t), drag_of(p.mu, v));
    EXPECT_NEAR(eq14(p, m.rate(t), m.accel(t), -v), truth.sensor.x(), 1e-12) << t;
  }
}

// Eq. (14) drops two terms of eq. (8): sensor.x - eq14 = (cos a - 1) drag - sin a lever_z (docs/model.md).
double dropped_terms_bound(const PaperAxisParams& p, const Reading& r) {
  return std::abs(1.0 - cos(p.alpha)) * std::abs(r.drag) + std::abs(sin(p.alpha)) * std::abs(r.lever.z());
}

TEST(PaperModel, WithThePapersAlphaDiffersFromPhysicsOnlyByTheDroppedTerms) {
  const Manoeuvre m;
  double worst = 0.0;
  for (double t = 0.0; t < 5.0; t += 0.01) {
    const double v = m.velocity_ned(t);
    const Reading truth = pitch_physics(kPaperFit, m.angle(t), m.rate(t), m.accel(t), drag_of(kPaperFit.mu, v));
    const double error = std::abs(eq14(kPaperFit, m.rate(t), m.accel(t), -v) - truth.sensor.x());
    EXPECT_LE(error, dropped_terms_bound(kPaperFit, truth) + 1e-12) << t;
    worst = std::max(worst, error);
  }
  EXPECT_GT(worst, 1e-6);  // the dropped terms are real, so the bound above is doing work
}

TEST(PaperModel, RollAxisIsThePitchModelWithTheDocumentedSignMapping) {
  const Manoeuvre m;
  for (const double alpha : {0.0, kPaperFit.alpha}) {
    PaperAxisParams p = kPaperFit;
    p.alpha = alpha;
    for (double t = 0.0; t < 5.0; t += 0.01) {
      const double v = m.velocity_ned(t);
      const Reading truth = roll_physics(p, m.angle(t), m.rate(t), m.accel(t), drag_of(p.mu, v));
      // omega' = -omega_x, v' = -V_Y, f' = f_y.
      EXPECT_NEAR(eq14(p, -m.rate(t), -m.accel(t), -v), truth.sensor.y(), dropped_terms_bound(p, truth) + 1e-12) << t;
    }
  }
}

TEST(PaperModel, PartialDerivativesForCeresMatchTheAnalyticOnes) {
  using Jet = ceres::Jet<double, 4>;
  const PaperAxisParams& p = kPaperFit;
  const PaperSample s{.omega = 1.3, .omega_dot = -4.2, .v = -2.5};
  const Jet f = paper_specific_force(paper_coefficients(Jet(p.r, 0), Jet(p.beta, 1), Jet(p.alpha, 2), Jet(p.mu, 3)), s);
  const double lever = s.omega * s.omega * cos(p.beta) + s.omega_dot * sin(p.beta);
  EXPECT_NEAR(f.a, eq14(p, s.omega, s.omega_dot, s.v), 1e-15);
  EXPECT_NEAR(f.v[0], -lever * cos(p.alpha), 1e-12);
  EXPECT_NEAR(f.v[1], -p.r * (-s.omega * s.omega * sin(p.beta) + s.omega_dot * cos(p.beta)) * cos(p.alpha), 1e-12);
  EXPECT_NEAR(f.v[2], kGravity * cos(p.alpha) + p.r * lever * sin(p.alpha), 1e-12);
  EXPECT_NEAR(f.v[3], -s.v * s.v, 1e-12);  // sign(v) v^2 with v < 0
}

TEST(PaperModel, DefaultsPredictNothing) {
  EXPECT_FALSE(validate(PaperAxisParams{}));
  EXPECT_EQ(eq14(PaperAxisParams{}, 2.0, 30.0, 5.0), 0.0);
}

TEST(PaperModel, ValidateRejectsNegativeOrNonFiniteValues) {
  EXPECT_TRUE(validate(PaperAxisParams{.r = -0.1}));
  EXPECT_TRUE(validate(PaperAxisParams{.mu = -0.01}));
  EXPECT_TRUE(validate(PaperAxisParams{.alpha = std::nan("")}));
}

// Gyro rate + ramp * t: the central difference is exact on it, so omega_dot must be the ramp.
ImuSeries ramp_series(const Eigen::Vector3d& rate, const Eigen::Vector3d& ramp, double h, int n) {
  ImuSeries s;
  for (int k = 0; k < n; ++k) {
    s.t.push_back(k * h);
    s.gyro.push_back(rate + ramp * (k * h));
    s.accel.push_back(Eigen::Vector3d(0.1 * k, -0.2 * k, -kGravity));
  }
  return s;
}

TEST(PreparePaperAxis, IntegratesEq11And12WithTheTrapezoidalRule) {
  // At a constant rate w: theta = w t exactly (trapezoidal is exact on it), v_X = g (1 - cos(w t)) / w, which the
  // trapezoidal rule reaches within t h^2 / 12 max|d2/dt2 g sin(w t)| = t h^2 g w^2 / 12.
  const double h = 0.01, w = 0.8;
  const auto samples = prepare_paper_axis(ramp_series({0, w, 0}, {0, 0, 0}, h, 300), PaperAxis::pitch);
  for (const PaperSample& s : samples) {
    EXPECT_NEAR(s.theta, w * s.t, 1e-12);
    EXPECT_NEAR(s.v, kGravity * (1.0 - cos(w * s.t)) / w, s.t * h * h * kGravity * w * w / 12.0 + 1e-12);
    EXPECT_EQ(s.omega, w);
    EXPECT_NEAR(s.omega_dot, 0.0, 1e-12);
    EXPECT_EQ(s.f, 0.1 * std::round(s.t / h));  // accel.x
  }
}

TEST(PreparePaperAxis, RollUsesMinusOmegaXItsDerivativeAndTheYAccelerometer) {
  // Rolling right at p: V_Y = g (1 - cos(p t)) / p (the thrust tilts toward +Y), so the paper-sign v is -V_Y.
  const double h = 0.01, p = 0.8;
  const auto samples = prepare_paper_axis(ramp_series({p, 0, 0}, {0, 0, 0}, h, 300), PaperAxis::roll);
  for (const PaperSample& s : samples) {
    EXPECT_EQ(s.omega, -p);
    EXPECT_NEAR(s.theta, -p * s.t, 1e-12);
    EXPECT_NEAR(s.v, -kGravity * (1.0 - cos(p * s.t)) / p, s.t * h * h * kGravity * p * p / 12.0 + 1e-12);
    EXPECT_EQ(s.f, -0.2 * std::round(s.t / h));  // accel.y
  }
  for (const PaperSample& s : prepare_paper_axis(ramp_series({0, 0, 0}, {1.5, 0.5, 0}, h, 30), PaperAxis::roll))
    EXPECT_NEAR(s.omega_dot, -1.5, 1e-9);
  for (const PaperSample& s : prepare_paper_axis(ramp_series({0, 0, 0}, {1.5, 0.5, 0}, h, 30), PaperAxis::pitch))
    EXPECT_NEAR(s.omega_dot, 0.5, 1e-9);
}

TEST(PreparePaperAxis, RejectsAnInvalidSeries) {
  ImuSeries s = ramp_series({0, 1, 0}, {0, 0, 0}, 0.01, 10);
  s.t[5] = s.t[4];
  EXPECT_THROW(prepare_paper_axis(s, PaperAxis::pitch), std::invalid_argument);
  s = ramp_series({0, 1, 0}, {0, 0, 0}, 0.01, 10);
  s.accel.pop_back();
  EXPECT_THROW(prepare_paper_axis(s, PaperAxis::pitch), std::invalid_argument);
}

// A pitch flight through the whole pipeline: gyro and accelerometer from physics, plus accelerometer noise.
TEST(PaperObjective, RmseAtTheTrueParametersIsTheNoiseAndGrowsAwayFromThem) {
  const Manoeuvre m;
  const double h = 0.005, sigma = 0.05;
  const int n = 4000;
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, sigma);
  ImuSeries series;
  double v_ned = 0.0;  // eq. (1) with U1 = g: V_X' = -g sin(theta), integrated far finer than the model does
  for (int k = 0; k < n; ++k) {
    const double t = k * h;
    if (k > 0) {
      const int steps = 50;
      for (int i = 0; i < steps; ++i) {
        const double ta = t - h + i * h / steps;
        v_ned -= h / steps * kGravity * sin(m.angle(ta + 0.5 * h / steps));
      }
    }
    const Reading r = pitch_physics(kPaperFit, m.angle(t), m.rate(t), m.accel(t), drag_of(kPaperFit.mu, v_ned));
    series.t.push_back(t);
    series.gyro.push_back({0.0, m.rate(t), 0.0});
    series.accel.push_back(r.sensor + Eigen::Vector3d(noise(rng), noise(rng), noise(rng)));
  }
  const auto samples = prepare_paper_axis(series, PaperAxis::pitch);
  const double at_truth = rmse(kPaperFit, samples);
  EXPECT_DOUBLE_EQ(objective(kPaperFit, samples), at_truth * std::sqrt(n));
  // The model's own errors (dropped terms, differentiation, integration) are far below the noise here, and the
  // RMSE of n = 4000 samples of N(0, sigma) is within a few percent of sigma.
  EXPECT_NEAR(at_truth, sigma, 0.05 * sigma);

  const std::vector<double> predicted = predict(kPaperFit, samples);
  ASSERT_EQ(predicted.size(), samples.size());
  double sum = 0.0;
  for (std::size_t k = 0; k < samples.size(); ++k) sum += std::pow(samples[k].f - predicted[k], 2);
  EXPECT_DOUBLE_EQ(std::sqrt(sum), objective(kPaperFit, samples));

  for (int i = 0; i < 4; ++i) {
    for (const double sign : {-1.0, 1.0}) {
      PaperAxisParams off = kPaperFit;
      double* value[] = {&off.r, &off.beta, &off.alpha, &off.mu};
      const double step[] = {0.02, 5.0 * kPi / 180.0, 0.5 * kPi / 180.0, 0.01};
      *value[i] += sign * step[i];
      EXPECT_GT(rmse(off, samples), at_truth) << "parameter " << i << " sign " << sign;
    }
  }
}

TEST(PaperObjective, EmptyDataHasZeroRmse) { EXPECT_EQ(rmse(kPaperFit, {}), 0.0); }

}  // namespace
}  // namespace imubridge::estimator
