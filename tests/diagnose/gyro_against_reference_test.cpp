// The gyro's bias against a reference attitude (diagnose/gyro_against_reference.hpp): found where it is, not read
// into a reference frame turned slightly from the gyro's, nothing where there is none.
#include "diagnose/gyro_against_reference.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>

#include "diagnose/signals.hpp"

namespace imubridge::diagnose {
namespace {

// 60 s at 200 Hz of a body turning about all three axes; the reference's attitude is the body's, the gyro reads
// the rate in a frame turned by `misalignment` (rotation vector) from it, plus `bias` and white noise.
Signals turning_flight(const Eigen::Vector3d& bias, const Eigen::Vector3d& misalignment, std::uint64_t seed) {
  constexpr double kRate = 200.0, kSeconds = 60.0;
  std::mt19937_64 random(seed);
  std::normal_distribution<double> noise(0.0, 0.01);  // rad/s per sample
  const Eigen::Matrix3d gyro_from_body = rotation_matrix(misalignment);
  Signals s;
  s.reference.emplace();
  Eigen::Quaterniond attitude = Eigen::Quaterniond::Identity();
  const auto n = static_cast<std::size_t>(kRate * kSeconds);
  for (std::size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) / kRate;
    const Eigen::Vector3d rate(0.8 * std::sin(1.3 * t), 0.6 * std::sin(0.7 * t + 1.0), 0.3 + 0.4 * std::sin(0.4 * t));
    s.t.push_back(t);
    s.reference->attitude.push_back(attitude);
    s.gyro.push_back(gyro_from_body * rate + bias + Eigen::Vector3d(noise(random), noise(random), noise(random)));
    attitude = (attitude * Eigen::Quaterniond(rotation_matrix(rate / kRate))).normalized();
  }
  return s;
}

TEST(GyroAgainstReference, FindsTheBiasBesideAMisalignedFrame) {
  const Eigen::Vector3d bias(0.02, -0.01, 0.005);
  // A frame turned by 2 deg: while yawing at 0.3 rad/s on average it reads 0.01 rad/s on x and y that are not a bias.
  const Signals s = turning_flight(bias, Eigen::Vector3d(0.02, -0.03, 0.01), 1);
  const auto g = gyro_against_reference(s, 0, s.size());
  ASSERT_TRUE(g.has_value());
  for (int axis = 0; axis < 3; ++axis) EXPECT_NEAR(g->bias[axis], bias[axis], 1e-3) << "axis " << axis;
  EXPECT_LT(g->p_value, 1e-6);
  EXPECT_GE(g->spans, 200u);
}

TEST(GyroAgainstReference, NamesNoBiasWhereThereIsNone) {
  const Signals s = turning_flight(Eigen::Vector3d::Zero(), Eigen::Vector3d(0.02, -0.03, 0.01), 2);
  const auto g = gyro_against_reference(s, 0, s.size());
  ASSERT_TRUE(g.has_value());
  EXPECT_LT(g->bias.norm(), 1e-3);
  EXPECT_GT(g->p_value, 0.01);
}

TEST(GyroAgainstReference, NeedsAReferenceAndEnoughSpans) {
  Signals s = turning_flight(Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), 3);
  EXPECT_FALSE(gyro_against_reference(s, 0, 200 * 3).has_value());  // 3 s: 12 spans
  s.reference.reset();
  EXPECT_FALSE(gyro_against_reference(s, 0, s.size()).has_value());
}

}  // namespace
}  // namespace imubridge::diagnose
