#include "estimator/full_model.hpp"

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <functional>

#include "estimator/constants.hpp"
#include "estimator/lever_arm_compensation.hpp"
#include "estimator/paper_model.hpp"

namespace imubridge::estimator {
namespace {

using std::cos;
using std::sin;

const PaperAxisParams kPaperFit{.r = 0.179, .beta = 85.12 * kPi / 180.0, .alpha = -0.3 * kPi / 180.0, .mu = 0.0386};

// Everything non-zero, so each term of the model shows.
FullModelParams general_params() {
  FullModelParams p;
  p.lever_arm = {0.12, -0.05, -0.08};
  p.mounting = {0.02, -0.04, 0.3};
  p.drag_linear = {0.35, 0.42};
  p.drag_quadratic = {0.04, 0.05};
  p.accel_bias = {0.03, -0.02, 0.05};
  return p;
}

// docs/model.md: the paper's pitch installation in 3-D terms.
FullModelParams pitch_installation(const PaperAxisParams& p) {
  FullModelParams full;
  full.lever_arm = p.r * Eigen::Vector3d(cos(p.beta), 0, -sin(p.beta));
  full.mounting = {0, p.alpha, 0};
  full.drag_quadratic = {p.mu, 0};
  return full;
}

// docs/estimator.md: the roll axis's installation, the pitch one turned +90 deg about z_b.
FullModelParams roll_installation(const PaperAxisParams& p) {
  FullModelParams full;
  full.lever_arm = p.r * Eigen::Vector3d(0, cos(p.beta), -sin(p.beta));
  full.mounting = {-p.alpha, 0, 0};
  full.drag_quadratic = {0, p.mu};
  return full;
}

double eq14(const PaperAxisParams& p, double omega, double omega_dot, double v_paper) {
  return paper_specific_force(paper_coefficients(p), PaperSample{.omega = omega, .omega_dot = omega_dot, .v = v_paper});
}

// An agile single-axis manoeuvre and a horizontal velocity profile, with exact derivatives.
double rate(double t) { return 0.25 * 3.1 * cos(3.1 * t) + 0.08 * 10.7 * cos(10.7 * t); }
double rate_dot(double t) { return -0.25 * 3.1 * 3.1 * sin(3.1 * t) - 0.08 * 10.7 * 10.7 * sin(10.7 * t); }
double velocity(double t) { return 3.0 * sin(0.4 * t) + 0.5; }

TEST(FullModel, PitchOnlyXRowIsEq14UpToTheDroppedTerms) {
  for (const double alpha : {0.0, kPaperFit.alpha}) {
    PaperAxisParams p = kPaperFit;
    p.alpha = alpha;
    const FullModelParams full = pitch_installation(p);
    for (double t = 0.0; t < 5.0; t += 0.01) {
      const double q = rate(t), q_dot = rate_dot(t), v = velocity(t);
      const Eigen::Vector3d f = predict_specific_force(
          full, {.gyro = {0, q, 0}, .gyro_rate = {0, q_dot, 0}, .velocity = {v, 0}, .thrust = kGravity});
      // Dropped by eq. (14): (cos a - 1) * drag and -sin a * lever_z, with the lever arm's z acceleration
      // -q_dot r_x - q^2 r_z for a pitch-only rotation.
      const double lever_z = -q_dot * full.lever_arm.x() - q * q * full.lever_arm.z();
      const double bound = std::abs(1.0 - cos(alpha)) * p.mu * v * v + std::abs(sin(alpha) * lever_z);
      EXPECT_NEAR(f.x(), eq14(p, q, q_dot, -v), bound + 1e-12) << "alpha " << alpha << " t " << t;
    }
  }
}

TEST(FullModel, RollOnlyYRowIsTheRollAxisModel) {
  const FullModelParams full = roll_installation(kPaperFit);
  for (double t = 0.0; t < 5.0; t += 0.01) {
    const double p = rate(t), p_dot = rate_dot(t), v = velocity(t);
    const Eigen::Vector3d f = predict_specific_force(
        full, {.gyro = {p, 0, 0}, .gyro_rate = {p_dot, 0, 0}, .velocity = {0, v}, .thrust = kGravity});
    const double lever_z = p_dot * full.lever_arm.y() - p * p * full.lever_arm.z();
    const double bound =
        std::abs(1.0 - cos(kPaperFit.alpha)) * kPaperFit.mu * v * v + std::abs(sin(kPaperFit.alpha) * lever_z);
    EXPECT_NEAR(f.y(), eq14(kPaperFit, -p, -p_dot, -v), bound + 1e-12) << t;
  }
}

// A rigid body in general motion, differentiated numerically: R(t) from ZYX Euler angles, w from R^T dR/dt,
// the IMU's acceleration from d2/dt2 of its world offset R(t) r. Nothing here uses the model's cross products.
Eigen::Matrix3d attitude(double t) {
  return (Eigen::AngleAxisd(0.7 * sin(0.9 * t), Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(0.3 * sin(2.3 * t + 0.4), Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(0.25 * sin(3.7 * t + 1.1), Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

constexpr double kStep = 1e-3;  // five-point stencils: truncation O(step^4), rounding O(eps / step^2)

// The concrete return type evaluates the Eigen expression before its temporaries go.
template <typename F>
auto first_derivative(const F& f, double t) -> decltype(f(t)) {
  return (f(t - 2 * kStep) - 8 * f(t - kStep) + 8 * f(t + kStep) - f(t + 2 * kStep)) / (12 * kStep);
}
template <typename F>
auto second_derivative(const F& f, double t) -> decltype(f(t)) {
  return (-f(t - 2 * kStep) + 16 * f(t - kStep) - 30 * f(t) + 16 * f(t + kStep) - f(t + 2 * kStep)) /
         (12 * kStep * kStep);
}

Eigen::Vector3d body_rate(double t) {
  const Eigen::Matrix3d skew = attitude(t).transpose() * first_derivative(attitude, t);
  return {skew(2, 1), skew(0, 2), skew(1, 0)};
}

TEST(FullModel, MatchesNumericalRigidBodyKinematicsInGeneralMotion) {
  const FullModelParams p = general_params();
  const Eigen::Matrix3d imu_to_body = Eigen::AngleAxisd(p.mounting.norm(), p.mounting.normalized()).toRotationMatrix();
  const auto offset = [&p](double t) -> Eigen::Vector3d { return attitude(t) * p.lever_arm; };
  for (double t = 0.0; t < 4.0; t += 0.05) {
    const Eigen::Vector2d v(2.0 * sin(t), -1.5 + cos(0.5 * t));
    const double thrust = kGravity + 0.8 * sin(1.3 * t);
    // Mass-centre specific force in body axes: the drag law per horizontal axis and -T.
    const Eigen::Vector3d f_cm(-(p.drag_linear.x() * v.x() + p.drag_quadratic.x() * std::abs(v.x()) * v.x()),
                               -(p.drag_linear.y() * v.y() + p.drag_quadratic.y() * std::abs(v.y()) * v.y()), -thrust);
    const Eigen::Vector3d f_body = f_cm + attitude(t).transpose() * second_derivative(offset, t);
    const Eigen::Vector3d expected = imu_to_body.transpose() * f_body + p.accel_bias;

    const FullModelInput in{.gyro = imu_to_body.transpose() * body_rate(t),
                            .gyro_rate = imu_to_body.transpose() * first_derivative(body_rate, t),
                            .velocity = v,
                            .thrust = thrust};
    EXPECT_LT((predict_specific_force(p, in) - expected).norm(), 1e-6) << t;
  }
}

TEST(FullModel, MountingRotationVectorIsTheDocumentedConvention) {
  // mounting = (0, a, 0) puts the sensor x axis at (cos a, 0, -sin a): at rest in hover it reads g sin a.
  const double a = 0.1;
  FullModelParams p;
  p.mounting = {0, a, 0};
  const Eigen::Vector3d f = predict_specific_force(p, {.thrust = kGravity});
  EXPECT_NEAR(f.x(), kGravity * sin(a), 1e-12);
  EXPECT_NEAR(f.y(), 0.0, 1e-12);
  EXPECT_NEAR(f.z(), -kGravity * cos(a), 1e-12);
}

TEST(FullModel, DefaultsDisableEverythingButThrust) {
  EXPECT_FALSE(validate(FullModelParams{}));
  const Eigen::Vector3d f = predict_specific_force(
      FullModelParams{}, {.gyro = {1, -2, 3}, .gyro_rate = {10, 20, -30}, .velocity = {5, -4}, .thrust = 9.0});
  EXPECT_EQ(f, Eigen::Vector3d(0, 0, -9.0));
}

TEST(FullModel, ValidateRejectsNegativeDragAndNonFiniteValues) {
  FullModelParams p;
  p.drag_linear.y() = -0.1;
  EXPECT_TRUE(validate(p));
  p = FullModelParams{};
  p.drag_quadratic.x() = -0.01;
  EXPECT_TRUE(validate(p));
  p = FullModelParams{};
  p.lever_arm.z() = std::nan("");
  EXPECT_TRUE(validate(p));
}

// The 13 parameters as one vector, in block order, for comparing the autodiff Jacobian with finite differences.
using Vector13d = Eigen::Matrix<double, 13, 1>;
template <typename T>
Eigen::Matrix<T, 3, 1> predict_stacked(const Eigen::Matrix<T, 13, 1>& x, const FullModelInput& in) {
  return predict_specific_force(x.data(), x.data() + 3, x.data() + 6, x.data() + 8, x.data() + 10, in);
}

TEST(FullModel, AutodiffJacobianMatchesFiniteDifferences) {
  const FullModelInput in{
      .gyro = {0.8, -1.1, 0.4}, .gyro_rate = {6.0, 3.0, -2.0}, .velocity = {1.7, -2.2}, .thrust = 10.1};
  for (const bool aligned : {true, false}) {  // zero mounting is the rotation's special case
    FullModelParams p = general_params();
    if (aligned) p.mounting.setZero();
    Vector13d x;
    x << p.lever_arm, p.mounting, p.drag_linear, p.drag_quadratic, p.accel_bias;

    using Jet = ceres::Jet<double, 13>;
    Eigen::Matrix<Jet, 13, 1> xj;
    for (int i = 0; i < 13; ++i) xj[i] = Jet(x[i], i);
    const Eigen::Matrix<Jet, 3, 1> f = predict_stacked(xj, in);
    for (int i = 0; i < 13; ++i) {
      const double h = 1e-6;
      Vector13d plus = x, minus = x;
      plus[i] += h;
      minus[i] -= h;
      const Eigen::Vector3d numeric = (predict_stacked(plus, in) - predict_stacked(minus, in)) / (2 * h);
      for (int row = 0; row < 3; ++row) EXPECT_NEAR(f[row].v[i], numeric[row], 1e-7) << aligned << " " << i;
    }
  }
}

TEST(LeverArmCompensation, InvertsTheModel) {
  const FullModelParams p = general_params();
  const LeverArmCompensator compensate(p);
  const FullModelInput in{
      .gyro = {0.8, -1.1, 0.4}, .gyro_rate = {6.0, 3.0, -2.0}, .velocity = {1.7, -2.2}, .thrust = 10.1};
  const Eigen::Vector3d f_cm = compensate.compensate(predict_specific_force(p, in), in.gyro, in.gyro_rate);
  EXPECT_NEAR(f_cm.x(), drag_specific_force(p.drag_linear.x(), p.drag_quadratic.x(), in.velocity.x()), 1e-12);
  EXPECT_NEAR(f_cm.y(), drag_specific_force(p.drag_linear.y(), p.drag_quadratic.y(), in.velocity.y()), 1e-12);
  EXPECT_NEAR(f_cm.z(), -in.thrust, 1e-12);
}

TEST(LeverArmCompensation, DefaultsPassTheMeasurementThrough) {
  const LeverArmCompensator compensate{FullModelParams{}};
  const Eigen::Vector3d accel(0.3, -0.2, -9.7);
  EXPECT_EQ(compensate.compensate(accel, {1, 2, 3}, {-4, 5, 6}), accel);
}

TEST(LeverArmCompensation, ToBodyUsesTheMountingRotation) {
  FullModelParams p;
  p.mounting = {0, 0.1, 0};
  const Eigen::Vector3d sensor_x = LeverArmCompensator(p).to_body(Eigen::Vector3d::UnitX());
  EXPECT_LT((sensor_x - Eigen::Vector3d(cos(0.1), 0, -sin(0.1))).norm(), 1e-15);
}

}  // namespace
}  // namespace imubridge::estimator
