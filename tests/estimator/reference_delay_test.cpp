// estimator::estimate_reference_delay on simulated flights whose reference is given as a receiver gives it
// (sim::ReferenceReceiver): delayed, slower than the IMU, rounded.
#include "estimator/reference_delay.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "sim/scenario.hpp"
#include "sim/simulator.hpp"

namespace imubridge::test {
namespace {

using Eigen::Vector3d;

struct Flight {
  estimator::ImuSeries series;  // the IMU as measured, the vehicle's attitude at each sample
  std::vector<double> reference_t;
  std::vector<Vector3d> reference_velocity;
};

Flight fly(const std::string& scenario, std::vector<std::string> effects, double imu_rate_hz = 200.0,
           double duration_s = 40.0) {
  sim::SimConfig config = sim::make_scenario(scenario, 3, duration_s, effects);
  config.imu.rate_hz = imu_rate_hz;
  Flight f;
  f.series.reference.emplace();
  sim::ReferenceReceiver receiver(config.reference);
  sim::simulate(config, [&](const sim::SimSample& s) {
    f.series.t.push_back(s.time_s);
    f.series.accel.push_back(s.measured.accel);
    f.series.gyro.push_back(s.measured.gyro);
    f.series.reference->attitude.push_back(s.truth.attitude);
    f.series.reference->velocity_ned.push_back(Vector3d::Zero());  // not read: the reference's own samples are
    if (const auto pose = receiver.next(s.truth)) {
      f.reference_t.push_back(pose->t);
      f.reference_velocity.push_back(pose->velocity_ned);
    }
  });
  return f;
}

estimator::ReferenceDelay estimate(const Flight& f) {
  return estimator::estimate_reference_delay(f.series, f.reference_t, f.reference_velocity);
}

// The paper's flight: the IMU 0.18 m from the mass centre, turned by its mounting, the attitude the vehicle's.
TEST(ReferenceDelay, AReferenceDelayedByAFifthOfASecondIsFoundWithin20Ms) {
  const estimator::ReferenceDelay d = estimate(fly("paper", {"reference_delay=0.2"}));
  ASSERT_TRUE(d.usable()) << estimator::describe(d);
  EXPECT_NEAR(d.delay_s, 0.2, 0.02) << estimator::describe(d);
  EXPECT_GT(d.correlation, 0.9);
  EXPECT_GT(d.curvature, 0.0);
}

TEST(ReferenceDelay, AGnssLikeReferenceAt10HzRoundedTo5CmPerSecondIsFoundWithin20Ms) {
  const estimator::ReferenceDelay d =
      estimate(fly("paper", {"reference_delay=0.2", "reference_rate=10", "reference_quantum=0.05"}));
  ASSERT_TRUE(d.usable()) << estimator::describe(d);
  EXPECT_NEAR(d.delay_s, 0.2, 0.02) << estimator::describe(d);
}

TEST(ReferenceDelay, A1kHzImuWithA5HzReferenceAndATiltedMountIsFoundWithin20Ms) {
  const estimator::ReferenceDelay d =
      estimate(fly("agile", {"reference_delay=0.15", "reference_rate=5", "imu_tilt=0.08"}, 1000.0));
  ASSERT_TRUE(d.usable()) << estimator::describe(d);
  EXPECT_NEAR(d.delay_s, 0.15, 0.02) << estimator::describe(d);
}

TEST(ReferenceDelay, AReferenceOnTimeIsFoundOnTime) {
  const estimator::ReferenceDelay d = estimate(fly("paper", {}));
  ASSERT_TRUE(d.usable()) << estimator::describe(d);
  EXPECT_NEAR(d.delay_s, 0.0, 0.01) << estimator::describe(d);
}

TEST(ReferenceDelay, AHoverCannotTellAndSaysWhy) {
  const estimator::ReferenceDelay d = estimate(fly("hover", {"reference_delay=0.2"}, 200.0, 30.0));
  EXPECT_FALSE(d.usable()) << estimator::describe(d);
  EXPECT_NE(estimator::describe(d).find("cannot be estimated"), std::string::npos) << estimator::describe(d);
}

TEST(ReferenceDelay, TooShortAReferenceCannotTell) {
  const estimator::ReferenceDelay d = estimate(fly("paper", {"reference_rate=5"}, 200.0, 3.0));
  EXPECT_FALSE(d.usable()) << estimator::describe(d);
  EXPECT_NE(d.unusable->find("too little reference data"), std::string::npos) << *d.unusable;
}

// The receiver itself: the delayed pose is the truth of `delay` before, on the rate's grid, rounded.
TEST(ReferenceReceiver, DelaysDecimatesAndRounds) {
  sim::ReferenceReceiver receiver({.delay_s = 0.1, .rate_hz = 10.0, .velocity_quantum = 0.5});
  std::vector<sim::ReferencePose> poses;
  for (int k = 0; k <= 1000; ++k) {
    sim::TrueState truth;
    truth.time_s = k * 0.001;
    truth.velocity_ned = Vector3d(truth.time_s * 10.0, 0.26, -0.26);
    truth.position_ned = Vector3d(truth.time_s, 0.0, 0.0);
    if (const auto pose = receiver.next(truth)) poses.push_back(*pose);
  }
  ASSERT_EQ(poses.size(), 10u);  // 0.1, 0.2, ..., 1.0 s: nothing before the first delayed state exists
  EXPECT_NEAR(poses.front().t, 0.1, 1e-9);
  EXPECT_NEAR(poses[1].t - poses[0].t, 0.1, 1e-9);
  EXPECT_NEAR(poses[4].position_ned.x(), poses[4].t - 0.1, 1e-9);
  EXPECT_DOUBLE_EQ(poses[4].velocity_ned.x(), std::round((poses[4].t - 0.1) * 10.0 / 0.5) * 0.5);
  EXPECT_DOUBLE_EQ(poses[4].velocity_ned.y(), 0.5);
  EXPECT_DOUBLE_EQ(poses[4].velocity_ned.z(), -0.5);
}

}  // namespace
}  // namespace imubridge::test
