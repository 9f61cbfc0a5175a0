// The `survey` scenario: the paper's flight with turns of the heading between legs (docs/simulator.md). It exists so
// that a constant wind turns through the body axes; these tests hold it to what the docs say it flies.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include "sim/flight.hpp"
#include "sim/scenario.hpp"
#include "sim/simulator.hpp"
#include "sim/trajectory.hpp"

namespace imubridge::sim {
namespace {

TEST(SurveyScenario, TurnsAreOffByDefaultSoTheOtherScenariosHoldTheirHeading) {
  EXPECT_FALSE(HeadingTurnConfig{}.enabled);
  for (const char* name : {"paper", "center", "hover", "agile", "climb"})
    EXPECT_FALSE(make_scenario(name, 1).flight.turns.enabled) << name;
  EXPECT_TRUE(make_scenario("survey", 1).flight.turns.enabled);
}

TEST(SurveyScenario, TurnsAreStepsOfTheYawRateBetweenLegs) {
  const HeadingTurnConfig config{.enabled = true};
  Rng rng(5);
  const CosineCurve yaw_rate = plan_heading_turns(config, 120.0, rng);
  EXPECT_LE(yaw_rate.end_time(), 119.0);
  EXPECT_GT(yaw_rate.end_time(), 90.0);
  int turns = 0;
  bool turning = false;
  for (double t = 0.0; t < 120.0; t += 0.01) {
    const double rate = yaw_rate.at(t).value;
    ASSERT_LE(std::abs(rate), config.rate_max_radps);
    if (t < config.first_start_s) {
      ASSERT_EQ(rate, 0.0);
    }
    if (!turning && rate != 0.0) ++turns;
    turning = rate != 0.0;
  }
  // A turn and a leg last 5-15 s together.
  EXPECT_GE(turns, 8);
  EXPECT_LE(turns, 24);
}

// The turns draw from their own stream: the roll and pitch plan is the paper's, whatever the turns.
TEST(SurveyScenario, KeepsThePapersRollAndPitchPlan) {
  const SimConfig paper = make_scenario("paper", 7, 40.0), survey = make_scenario("survey", 7, 40.0);
  FlightPlan a(paper.flight.manoeuvres, paper.flight.vertical, 40.0, Rng(3), Rng(4));
  FlightPlan b(survey.flight.manoeuvres, survey.flight.vertical, 40.0, Rng(3), Rng(4), survey.flight.turns, Rng(5));
  bool turned = false;
  for (double t = 0.0; t < 40.0; t += 0.005) {
    const FlightReference ra = a.at(t), rb = b.at(t);
    ASSERT_EQ(ra.roll.value, rb.roll.value) << t;
    ASSERT_EQ(ra.pitch.value, rb.pitch.value) << t;
    EXPECT_EQ(ra.yaw_rate, 0.0);
    turned = turned || rb.yaw_rate != 0.0;
  }
  EXPECT_TRUE(turned);
}

// The flight: the vehicle follows the turns at well under 1 rad/s, the heading covers a wide arc, and the position
// hold keeps it near the start, as in the paper's flight.
TEST(SurveyScenario, TheVehicleTurnsThroughAWideArcAndStaysNearItsStart) {
  const std::vector<SimSample> flight = simulate(make_scenario("survey", 11, 40.0));
  double heading = 0.0, lowest = 0.0, highest = 0.0, fastest_yaw = 0.0, fastest_ground = 0.0, farthest = 0.0;
  double previous_yaw = flight.front().truth.euler.z();
  for (const SimSample& s : flight) {
    double turn = s.truth.euler.z() - previous_yaw;
    turn -= 2 * std::numbers::pi * std::round(turn / (2 * std::numbers::pi));  // unwrapped
    previous_yaw = s.truth.euler.z();
    heading += turn;
    lowest = std::min(lowest, heading), highest = std::max(highest, heading);
    fastest_yaw = std::max(fastest_yaw, std::abs(s.truth.omega.z()));
    fastest_ground = std::max(fastest_ground, s.truth.velocity_ned.head<2>().norm());
    farthest = std::max(farthest, s.truth.position_ned.head<2>().norm());
  }
  EXPECT_GT(highest - lowest, std::numbers::pi / 2) << "the heading covers more than a quarter turn";
  EXPECT_LT(fastest_yaw, 0.8);
  EXPECT_LT(fastest_ground, 4.0);
  EXPECT_LT(farthest, 10.0);
}

}  // namespace
}  // namespace imubridge::sim
