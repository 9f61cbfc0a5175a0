#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "estimator/constants.hpp"
#include "estimator/velocity.hpp"

namespace imubridge::estimator {
namespace {

std::vector<double> times(int n, double h) {
  std::vector<double> t(n);
  for (int k = 0; k < n; ++k) t[k] = k * h;
  return t;
}

TEST(DeadReckoning, PitchOnlyIsThePapersEq12WithTheNedSign) {
  const auto t = times(2000, 0.005);
  std::vector<double> q(t.size());
  std::vector<Eigen::Vector3d> gyro(t.size());
  for (std::size_t k = 0; k < t.size(); ++k) {
    q[k] = 0.4 * std::cos(2.0 * t[k]) + 0.1 * std::sin(7.0 * t[k]);
    gyro[k] = {0.0, q[k], 0.0};
  }
  const PitchIntegration paper = integrate_pitch(t, q);
  const DeadReckoning dr = dead_reckon(t, gyro, std::vector<double>(t.size(), kGravity));
  for (std::size_t k = 0; k < t.size(); ++k) {
    // Rotations about one axis compose exactly, so the attitude is R_y(theta_k) ...
    const Eigen::Quaterniond expected(Eigen::AngleAxisd(paper.theta[k], Eigen::Vector3d::UnitY()));
    EXPECT_LT(dr.attitude[k].angularDistance(expected), 1e-9) << k;
    // ... and with T = g the NED velocity is minus the paper's v_X (docs/model.md).
    EXPECT_NEAR(dr.velocity_ned[k].x(), -paper.v[k], 1e-9) << k;
    EXPECT_NEAR(dr.velocity_ned[k].y(), 0.0, 1e-12) << k;
  }
}

TEST(DeadReckoning, LevelThrustAboveGravityClimbs) {
  // NED: climbing is negative Z. Level, T = g + 1: V_Z = -t exactly (a constant acceleration).
  const auto t = times(100, 0.01);
  const DeadReckoning dr = dead_reckon(t, std::vector<Eigen::Vector3d>(t.size(), Eigen::Vector3d::Zero()),
                                       std::vector<double>(t.size(), kGravity + 1.0));
  for (std::size_t k = 0; k < t.size(); ++k)
    EXPECT_LT((dr.velocity_ned[k] - Eigen::Vector3d(0, 0, -t[k])).norm(), 1e-12);
}

TEST(DeadReckoning, StartsFromTheGivenStateAndRejectsMismatchedInputs) {
  const auto t = times(3, 0.01);
  const std::vector<Eigen::Vector3d> gyro(3, Eigen::Vector3d::Zero());
  const Eigen::Quaterniond q0(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()));
  const DeadReckoning dr = dead_reckon(t, gyro, std::vector<double>(3, kGravity), q0, Eigen::Vector3d(1, 2, 0));
  EXPECT_LT(dr.attitude.back().angularDistance(q0), 1e-12);
  EXPECT_LT((dr.velocity_ned.back() - Eigen::Vector3d(1, 2, 0)).norm(), 1e-12);  // level hover keeps its velocity
  EXPECT_THROW(dead_reckon(t, gyro, std::vector<double>(2, kGravity)), std::invalid_argument);
  EXPECT_TRUE(dead_reckon({}, {}, {}).velocity_ned.empty());
}

TEST(BodyVelocity, RotatesTheReferenceIntoBodyAxes) {
  // Facing east (yaw +90 deg) while moving north: north is on the left, -y in FRD.
  const std::vector<Eigen::Quaterniond> q{Eigen::Quaterniond(Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d::UnitZ()))};
  const std::vector<Eigen::Vector3d> v{Eigen::Vector3d(1, 0, 0)};
  EXPECT_LT((body_velocity(q, v)[0] - Eigen::Vector3d(0, -1, 0)).norm(), 1e-15);
  // Nose up 30 deg while moving north: the motion is partly along +x and partly along +z (down, in body axes).
  const std::vector<Eigen::Quaterniond> pitched{
      Eigen::Quaterniond(Eigen::AngleAxisd(kPi / 6, Eigen::Vector3d::UnitY()))};
  EXPECT_LT((body_velocity(pitched, v)[0] - Eigen::Vector3d(std::cos(kPi / 6), 0, std::sin(kPi / 6))).norm(), 1e-15);
}

TEST(IntegratePitch, HonoursTheInitialValues) {
  const auto t = times(3, 0.1);
  const std::vector<double> q(3, 0.0);
  const PitchIntegration p = integrate_pitch(t, q, 0.2, 1.5);
  // Constant pitch 0.2: theta stays, v grows at g sin(0.2).
  EXPECT_NEAR(p.theta[2], 0.2, 1e-15);
  EXPECT_NEAR(p.v[2], 1.5 + 0.2 * kGravity * std::sin(0.2), 1e-12);
}

}  // namespace
}  // namespace imubridge::estimator
