// The plausibility table: values no airframe has are named with their limit, and the limits can be overridden.
#include "identification/plausibility.hpp"

#include <gtest/gtest.h>

#include <stdexcept>
#include <string>
#include <vector>

namespace imubridge::estimator {
namespace {

bool names(const std::vector<Implausibility>& list, const std::string& limit) {
  for (const auto& i : list) {
    if (i.limit == limit) return true;
  }
  return false;
}

TEST(Plausibility, AQuadrotorsValuesPass) {
  FullModelParams p;
  p.lever_arm = {0.1, 0.02, -0.05};
  p.wind = {3.0, -2.0};
  p.accel_scale = {0.02, -0.01, 0.0};
  p.accel_cross(0, 1) = 0.01;
  p.gyro_bias = {0.01, -0.02, 0.005};
  p.accel_bias = {0.2, -0.1, 0.3};
  p.time_offset = 0.02;
  EXPECT_TRUE(check_plausibility(p).empty());
}

TEST(Plausibility, EachLimitIsNamedWhenExceeded) {
  const auto one = [](auto change, const std::string& limit) {
    FullModelParams p;
    change(p);
    const auto found = check_plausibility(p);
    ASSERT_EQ(found.size(), 1u) << limit;
    EXPECT_EQ(found.front().limit, limit);
    EXPECT_NE(found.front().message.find("--limit " + limit), std::string::npos) << found.front().message;
  };
  one([](FullModelParams& p) { p.lever_arm = {1.0, 0.0, 0.0}; }, "lever_arm");  // 1 m on a 0.35 m quadrotor
  one([](FullModelParams& p) { p.wind = {30.0, 0.0}; }, "wind");
  one([](FullModelParams& p) { p.accel_scale.x() = -0.5; }, "accel_scale");
  one([](FullModelParams& p) { p.accel_cross(1, 0) = 0.5; }, "accel_cross");
  one([](FullModelParams& p) { p.gyro_bias.y() = 0.53; }, "gyro_bias");
  one([](FullModelParams& p) { p.accel_bias.z() = -2.0; }, "accel_bias");
  one([](FullModelParams& p) { p.time_offset = 0.2; }, "time_offset");
}

TEST(Plausibility, LimitsCanBeOverriddenAndBadOverridesAreRefused) {
  FullModelParams p;
  p.lever_arm = {0.8, 0.0, 0.0};
  PlausibilityLimits limits;
  EXPECT_TRUE(names(check_plausibility(p, limits), "lever_arm"));
  override_limit(limits, "lever_arm=1.2");  // a large octocopter
  EXPECT_TRUE(check_plausibility(p, limits).empty());
  EXPECT_DOUBLE_EQ(limits.lever_arm, 1.2);
  for (const char* bad : {"lever_arm", "lever_arm=", "lever_arm=-1", "lever_arm=0", "lever_arm=x", "wingspan=2"})
    EXPECT_THROW(override_limit(limits, bad), std::invalid_argument) << bad;
  try {
    override_limit(limits, "wingspan=2");
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("lever_arm"), std::string::npos) << e.what();  // names the valid ones
  }
}

TEST(Plausibility, TheTableListsEveryLimit) {
  const auto table = limit_table();
  ASSERT_EQ(table.size(), 9u);
  EXPECT_EQ(table.back().first, "drag_quadratic");
  EXPECT_EQ(table.front().first, "lever_arm");
  EXPECT_DOUBLE_EQ(table.front().second, 0.5);
}

// --limit's help is made from the table: every limit a refusal can name (drag_linear, drag_quadratic included) is
// there.
TEST(Plausibility, TheHelpNamesEveryLimitWithItsUnitAndDefault) {
  const std::string help = limit_help();
  for (const auto& [name, value] : limit_table()) EXPECT_NE(help.find(name + " ("), std::string::npos) << name;
  EXPECT_NE(help.find("drag_quadratic (1/m, default 0.4)"), std::string::npos) << help;
  EXPECT_NE(help.find("accel_scale (default 0.1)"), std::string::npos) << help;
}

// A drag fitted to nothing (eq. (12)'s drifting velocity takes mu to ~1e-6) is said, axis by axis.
TEST(Plausibility, ADragTooSmallToSeeIsSaid) {
  FullModelParams p;
  p.drag_quadratic = {1e-6, 0.04};  // the second: the paper's mu, 1 m/s^2 at 5 m/s
  const std::vector<std::string> lines = negligible_drag(p);
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_NE(lines.front().find("no usable drag on x"), std::string::npos) << lines.front();
  p.drag_linear.x() = 0.3;  // 1.5 m/s^2 at 5 m/s
  EXPECT_TRUE(negligible_drag(p).empty());
}

}  // namespace
}  // namespace imubridge::estimator
