// The rules by which `imubridge diagnose` keeps a model (docs/effects.md, "Plausibility and bounds", "The
// significance rule"): an implausible base is fitted again inside the plausibility table, not carried on; a training
// window too short to tell the drag is refused with its length; every candidate is judged by what users fly with (the
// velocity with a reference, the filter's likelihood from the IMU alone) and says so.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "diagnose/search.hpp"
#include "estimator/imu_series.hpp"
#include "sim/imu_series.hpp"
#include "sim/scenario.hpp"
#include "sim/simulator.hpp"

namespace imubridge::diagnose {
namespace {

estimator::ImuSeries paper_flight(std::vector<std::string> effects = {}) {
  return sim::imu_series(sim::simulate(sim::make_scenario("paper", 3, 50.0, effects)));
}

DiagnoseOptions options(VelocitySource velocity, int max_steps) {
  DiagnoseOptions o;
  o.model = ModelKind::full;
  o.velocity = velocity;
  o.train = estimator::TimeWindow{0.0, 30.0};
  o.validate = estimator::TimeWindow{30.0, 50.0};
  o.max_steps = max_steps;
  return o;
}

TEST(DiagnoseRules, AnImplausibleBaseIsFittedAgainInsideThePlausibilityTable) {
  // The simulated IMU sits 0.179 m from the mass centre; a table that allows 0.1 m makes the first fit implausible.
  DiagnoseOptions o = options(VelocitySource::reference, 0);
  o.limits.lever_arm = 0.1;
  const Diagnosis d = run_diagnosis(paper_flight(), o);
  EXPECT_TRUE(d.base.implausible.empty()) << d.base.implausible.front();
  EXPECT_LE(d.final_params.full.lever_arm.norm(), 0.1 + 1e-9);
  const bool said = std::any_of(d.warnings.begin(), d.warnings.end(), [](const std::string& w) {
    return w.find("first fit was implausible") != std::string::npos && w.find("lever arm") != std::string::npos;
  });
  EXPECT_TRUE(said);
  // With the table's own limit the same flight's base is plausible and nothing is refitted.
  const Diagnosis plain = run_diagnosis(paper_flight(), options(VelocitySource::reference, 0));
  EXPECT_NEAR(plain.final_params.full.lever_arm.norm(), 0.179, 0.01);
  EXPECT_TRUE(plain.warnings.empty() || std::none_of(plain.warnings.begin(), plain.warnings.end(), [](const auto& w) {
                return w.find("first fit was implausible") != std::string::npos;
              }));
}

// Issue 25's linear drag with a time offset, from the IMU alone with the table's own limits (seed 21, which the
// sweep found it on): without the time offset the drag on y fits 2.3 1/s, past the table's 2, and the candidate was
// refused whole, so nothing was found. Held at zero on y, the drag on x is found; once the time offset is in, the y
// axis is fitted again and placed.
TEST(DiagnoseRules, AnAxisPastThePlausibilityTableIsHeldAtZeroUntilTheModelPlacesIt) {
  estimator::ImuSeries series = sim::imu_series(sim::simulate(sim::make_scenario(
      "paper", 21, 50.0, std::vector<std::string>{"linear_drag=1", "quadratic_drag=0", "time_offset=0.01"})));
  series.reference.reset();
  const Diagnosis d = run_diagnosis(series, options(VelocitySource::filter, 3));
  ASSERT_EQ(d.steps.size(), 2u) << (d.steps.empty() ? "nothing added" : "added " + d.steps.back().effect);
  EXPECT_EQ(d.steps[0].effect, "linear_drag");
  EXPECT_EQ(d.steps[1].effect, "time_offset");
  const auto chosen = std::find_if(d.steps[0].candidates.begin(), d.steps[0].candidates.end(),
                                   [](const CandidateTrial& c) { return c.effect == "linear_drag"; });
  ASSERT_NE(chosen, d.steps[0].candidates.end());
  EXPECT_EQ(chosen->held_at_zero, std::vector<std::string>{"linear_drag.k.y"});
  EXPECT_NE(chosen->held.find("k.y held at 0"), std::string::npos) << chosen->held;
  for (const ParameterEstimate& p : d.steps[0].params) {
    if (p.name == "k.y") {
      EXPECT_EQ(p.value, 0.0);
    }
  }
  EXPECT_NE(d.steps[1].released.find("k.y"), std::string::npos) << d.steps[1].released;
  EXPECT_NEAR(d.final_params.full.drag_linear.x(), 1.0, 0.1);
  EXPECT_NEAR(d.final_params.full.drag_linear.y(), 1.0, 0.1);
  EXPECT_NEAR(d.final_params.full.time_offset, 0.01, 0.001);
}

// A hidden wind raises the paper model's mu on y past the table (0.49 1/m; tests/cli/cli_loop_test.cpp's flight),
// which was carried on with a warning. Fitted again within the table, the base is plausible (the CLI's loop on that
// flight still adds the wind and the time offset: LoopToEstimator).
TEST(DiagnoseRules, AnImplausiblePaperDragIsFittedAgainInsideThePlausibilityTable) {
  DiagnoseOptions o = options(VelocitySource::reference, 2);
  o.model = ModelKind::paper;
  o.train = estimator::TimeWindow{0.0, 24.0};
  o.validate = estimator::TimeWindow{24.0, 40.0};
  const Diagnosis d =
      run_diagnosis(sim::imu_series(sim::simulate(sim::make_scenario(
                        "paper", 11, 40.0, std::vector<std::string>{"wind=3,1.5", "time_offset=0.02"}))),
                    o);
  EXPECT_TRUE(d.base.implausible.empty()) << d.base.implausible.front();
  const bool said = std::any_of(d.warnings.begin(), d.warnings.end(), [](const std::string& w) {
    return w.find("first fit was implausible") != std::string::npos &&
           w.find("mu within [0, 0.4]") != std::string::npos;
  });
  EXPECT_TRUE(said);
  for (const ParameterEstimate& p : d.base.base_params) {
    if (p.unit == "1/m") {
      EXPECT_LE(p.value, 0.4) << p.name;
    }
  }
  // The time offset the flight hides is still the first step.
  ASSERT_FALSE(d.steps.empty());
  EXPECT_EQ(d.steps.front().effect, "time_offset");
}

TEST(DiagnoseRules, ATrainingWindowTooShortToTellTheDragIsRefusedWithItsLength) {
  DiagnoseOptions o = options(VelocitySource::reference, 1);
  o.train = estimator::TimeWindow{0.0, 1.6};
  try {
    (void)run_diagnosis(paper_flight(), o);
    FAIL() << "a 1.6-s training window was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("1.6 s"), std::string::npos) << e.what();
  }
}

TEST(DiagnoseRules, EveryCandidateIsJudgedByTheVelocityWithAReference) {
  const DiagnoseOptions o = options(VelocitySource::reference, 2);
  const Diagnosis d = run_diagnosis(paper_flight(), o);
  ASSERT_TRUE(d.zero_velocity);
  double before = d.base.velocity->validation.horizontal;
  std::size_t tried = 0;
  const auto check = [&](const std::vector<CandidateTrial>& candidates) {
    for (const CandidateTrial& c : candidates) {
      if (!c.skipped.empty()) continue;
      ++tried;
      ASSERT_TRUE(c.velocity_validation) << c.effect;
      EXPECT_FALSE(c.likelihood_validation) << c.effect;
      if (c.rejected_by.rfind("velocity rule", 0) == 0) {
        // Refused because it flew worse, beyond what the validation can tell apart.
        EXPECT_GT(*c.velocity_validation, (1.0 + o.flight_tolerance) * before) << c.effect;
      }
    }
  };
  for (const Step& s : d.steps) {
    check(s.candidates);
    // No step kept flies worse than the model before it.
    ASSERT_TRUE(s.fit.velocity);
    EXPECT_LE(s.fit.velocity->validation.horizontal, (1.0 + o.flight_tolerance) * before) << s.effect;
    before = s.fit.velocity->validation.horizontal;
  }
  check(d.last_candidates);
  EXPECT_GT(tried, 0u);
  // On this flight no candidate lowers the residual while it flies worse; the real flight where one does, and the
  // residual alone takes it, is RealFlightLoop.AStepThatLowersTheResidualButFliesWorseIsRefused.
}

TEST(DiagnoseRules, FromTheImuAloneEveryCandidateIsJudgedByTheFiltersLikelihood) {
  const Diagnosis d = run_diagnosis(paper_flight(), options(VelocitySource::filter, 2));
  // The base has no drag: the filter reads no velocity from the accelerometer, and a likelihood would only rank
  // models that all fly zero velocity. The first step with drag has one.
  EXPECT_FALSE(d.base.likelihood);
  ASSERT_FALSE(d.steps.empty());
  ASSERT_TRUE(d.steps.front().fit.likelihood) << d.steps.front().effect;
  double before = d.steps.front().fit.likelihood->validation;
  std::size_t judged = 0;
  const auto check = [&](const std::vector<CandidateTrial>& candidates) {
    for (const CandidateTrial& c : candidates) {
      if (!c.skipped.empty()) continue;
      ASSERT_TRUE(c.likelihood_validation) << c.effect;
      ++judged;
      // A candidate that passes the residual's rules but lowers the likelihood is refused by the likelihood rule.
      if (c.rejected_by.rfind("likelihood rule", 0) == 0) {
        EXPECT_LT(*c.likelihood_validation, before - DiagnoseOptions{}.flight_tolerance * std::abs(before));
      }
    }
  };
  for (std::size_t i = 1; i < d.steps.size(); ++i) {
    check(d.steps[i].candidates);
    ASSERT_TRUE(d.steps[i].fit.likelihood);
    EXPECT_GE(d.steps[i].fit.likelihood->validation, before - DiagnoseOptions{}.flight_tolerance * std::abs(before));
    before = d.steps[i].fit.likelihood->validation;
  }
  check(d.last_candidates);
  EXPECT_GT(judged, 0u);
}

// The vibration of a real airframe buries a drag in the specific force (the X500's residual is 2.1 m/s^2 RMS), while
// the estimator filters it out of the velocity: with the reference, the velocity a first drag gives shows it.
TEST(DiagnoseRules, AFirstDragTheNoiseHidesFromTheResidualIsAddedByTheVelocityItGives) {
  // White noise of 0.05 m/s^2/sqrt(Hz) (0.5 m/s^2 per sample at 200 Hz) on the agile flight and its quadratic drag:
  // the drag lowers the validation residual by about 1 %, under the minimum gain.
  const std::vector<std::string> noise{"accel_noise=0.05"};
  const estimator::ImuSeries flight = sim::imu_series(sim::simulate(sim::make_scenario("agile", 42, 120.0, noise)));
  DiagnoseOptions o = options(VelocitySource::reference, 1);
  o.train = estimator::TimeWindow{0.0, 60.0};
  o.validate = estimator::TimeWindow{60.0, 120.0};
  const Diagnosis d = run_diagnosis(flight, o);
  ASSERT_EQ(d.steps.size(), 1u);
  EXPECT_EQ(d.steps[0].effect, "quadratic_drag");
  EXPECT_GT(d.steps[0].fit.rmse_validation, (1.0 - o.min_improvement) * d.base.rmse_validation);
  ASSERT_TRUE(d.steps[0].fit.velocity && d.zero_velocity);
  EXPECT_LT(d.steps[0].fit.velocity->validation.horizontal, 0.7 * d.zero_velocity->validation.horizontal);
  for (const CandidateTrial& c : d.steps[0].candidates) {
    if (c.effect == "quadratic_drag") {
      EXPECT_NE(c.admitted_by.find("the velocity's test"), std::string::npos);
    }
    // A drag that flies worse than not moving is not made significant by the test.
    if (c.velocity_test_p && c.velocity_validation && *c.velocity_validation > d.zero_velocity->validation.horizontal) {
      EXPECT_FALSE(c.significant) << c.effect;
    }
  }
  // The residual's rules alone add nothing.
  o.flight_rules = false;
  EXPECT_TRUE(run_diagnosis(flight, o).steps.empty());
}

TEST(DiagnoseRules, TheVelocitysTestCountsCorrelatedGainsAsFewerSamples) {
  // Seconds whose gain alternates about a positive mean show it clearly; the same values in two runs (each half the
  // window, like a velocity error held over a leg) are worth two seconds, and the test says so.
  constexpr std::size_t kSeconds = 40;
  std::vector<double> alternating, runs, negative;
  for (std::size_t b = 0; b < kSeconds; ++b) {
    alternating.push_back(1.0 + ((b % 2 == 0) ? 0.8 : -0.8));
    runs.push_back(1.0 + ((b < kSeconds / 2) ? 0.8 : -0.8));
    negative.push_back(-alternating.back());
  }
  EXPECT_LT(velocity_gain_test(alternating).p_value, 1e-6);
  EXPECT_GT(velocity_gain_test(runs).p_value, 0.01);
  EXPECT_EQ(velocity_gain_test(negative).p_value, 1.0);
}

}  // namespace
}  // namespace imubridge::diagnose
