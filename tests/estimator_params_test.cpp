#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "estimator/params.hpp"

namespace imubridge::estimator {
namespace {

using nlohmann::json;

ModelParams identified() {
  ModelParams p;
  p.paper_x = {.r = 0.179, .beta = 85.12 * kPi / 180.0, .alpha = -0.3 * kPi / 180.0, .mu = 0.0386};
  p.paper_y = {.r = 0.05, .beta = 1.2, .alpha = 0.004, .mu = 0.03};
  p.full.lever_arm = {0.12, -0.04, -0.06};
  p.full.mounting = {0.01, -0.02, 0.05};
  p.full.drag_linear = {0.35, 0.4};
  p.full.drag_quadratic = {0.04, 0.05};
  p.full.accel_bias = {0.05, -0.03, 0.1};
  p.identification = {.method = "ga+lm",
                      .seed = 42,
                      .fit_windows = {{0.0, 33.0}},
                      .validation_windows = {{33.0, 60.0}, {70.0, 80.5}},
                      .std_errors = {{"paper.x.r", 0.002}, {"full.lever_arm.0", 0.001}},
                      .rmse = {{"paper.x.fit", 0.578 / std::sqrt(6600.0)}}};
  return p;
}

TEST(ModelParamsJson, RoundTripsThroughTextExactly) {
  const ModelParams p = identified();
  EXPECT_EQ(json::parse(json(p).dump(2)).get<ModelParams>(), p);
}

TEST(ModelParamsJson, CarriesDegreesBesideRadiansForPeople) {
  const json j = identified();
  EXPECT_EQ(j.at("version"), kParamsVersion);
  EXPECT_NEAR(j["paper"]["x"]["beta_deg"].get<double>(), 85.12, 1e-12);
  EXPECT_NEAR(j["paper"]["x"]["alpha_deg"].get<double>(), -0.3, 1e-12);
  EXPECT_NEAR(j["full"]["mounting_deg"][2].get<double>(), 0.05 * 180.0 / kPi, 1e-12);
}

TEST(ModelParamsJson, DegreesAloneAreEnough) {
  const auto p = json::parse(R"({"paper": {"x": {"r": 0.2, "beta_deg": 90, "alpha_deg": -0.3}},
                                 "full": {"mounting_deg": [0, 180, 0]}})")
                     .get<ModelParams>();
  EXPECT_NEAR(p.paper_x.beta, kPi / 2, 1e-15);
  EXPECT_NEAR(p.paper_x.alpha, -0.3 * kPi / 180.0, 1e-15);
  EXPECT_NEAR(p.full.mounting.y(), kPi, 1e-15);
}

TEST(ModelParamsJson, RefusesRadiansAndDegreesThatDisagree) {
  json j = identified();
  j["paper"]["y"]["alpha_deg"] = 1.0;  // edited by hand, radians left as they were
  EXPECT_THROW(j.get<ModelParams>(), std::invalid_argument);
  j = identified();
  j["full"]["mounting_deg"][0] = 10.0;
  EXPECT_THROW(j.get<ModelParams>(), std::invalid_argument);
}

TEST(ModelParamsJson, MissingKeysMeanDefaultsAndDefaultsDisableCompensation) {
  const auto p = json::parse("{}").get<ModelParams>();
  EXPECT_EQ(p, ModelParams{});
  EXPECT_EQ(p.full.lever_arm, Eigen::Vector3d::Zero());
  EXPECT_EQ(p.full.mounting, Eigen::Vector3d::Zero());
  EXPECT_EQ(p.full.drag_linear + p.full.drag_quadratic, Eigen::Vector2d::Zero());
  EXPECT_EQ(p.full.accel_bias, Eigen::Vector3d::Zero());
  EXPECT_EQ(p.paper_x.r, 0.0);
  EXPECT_EQ(p.paper_x.alpha, 0.0);
  EXPECT_EQ(p.paper_x.mu, 0.0);
  EXPECT_TRUE(p.identification.method.empty());
  // A partial file keeps what it says and defaults the rest.
  const auto partial = json::parse(R"({"full": {"drag_linear": [0.3, 0.4]}})").get<ModelParams>();
  EXPECT_EQ(partial.full.drag_linear, Eigen::Vector2d(0.3, 0.4));
  EXPECT_EQ(partial.full.lever_arm, Eigen::Vector3d::Zero());
}

TEST(ModelParamsJson, RefusesOutOfRangeValuesOtherVersionsAndWrongTypes) {
  json j = identified();
  j["paper"]["x"]["mu"] = -0.1;
  EXPECT_THROW(j.get<ModelParams>(), std::invalid_argument);
  j = identified();
  j["full"]["drag_quadratic"] = {0.04, -0.05};
  EXPECT_THROW(j.get<ModelParams>(), std::invalid_argument);
  j = identified();
  j["version"] = kParamsVersion + 1;
  EXPECT_THROW(j.get<ModelParams>(), std::invalid_argument);
  j = identified();
  j["identification"]["fit_windows"] = {{5.0, 5.0}};
  EXPECT_THROW(j.get<ModelParams>(), std::invalid_argument);
  j = identified();
  j["full"]["lever_arm"] = "0.1";
  EXPECT_THROW(j.get<ModelParams>(), json::type_error);
  j = identified();
  j["full"]["lever_arm"] = {0.1, 0.2};  // three values expected
  EXPECT_THROW(j.get<ModelParams>(), json::exception);
}

}  // namespace
}  // namespace imubridge::estimator
