#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "estimator/drag_velocity.hpp"
#include "estimator/params.hpp"
#include "tests/support/temp_dir.hpp"

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
  p.full.accel_scale = {0.01, -0.02, 0.005};
  p.full.accel_cross << 0.0, 0.03, -0.01, 0.02, 0.0, 0.004, -0.006, 0.001, 0.0;
  p.full.gyro_bias = {0.002, -0.001, 0.0005};
  p.full.time_offset = -0.012;
  p.full.wind = {2.5, -1.25};
  p.full.wind_heading = 0.7;
  p.conditions_flight = "imu:0123456789abcdef";
  p.effects = {"linear_drag", "wind", "accel_scale", "accel_cross", "gyro_bias", "time_offset"};
  p.identification = {.method = "ga+lm",
                      .seed = 42,
                      .fit_windows = {{0.0, 33.0}},
                      .validation_windows = {{33.0, 60.0}, {70.0, 80.5}},
                      .std_errors = {{"paper.x.r", 0.002}, {"full.lever_arm.0", 0.001}},
                      .rmse = {{"paper.x.fit", 0.578 / std::sqrt(6600.0)}},
                      .transfer_offset_std = 0.45};
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
  EXPECT_THROW(j.get<ModelParams>(), std::invalid_argument);
  j = identified();
  j["full"]["lever_arm"] = {0.1, 0.2};  // three values expected
  EXPECT_THROW(j.get<ModelParams>(), std::invalid_argument);
  j = identified();
  j["identification"]["transfer_offset_std"] = -0.1;
  EXPECT_THROW(j.get<ModelParams>(), std::invalid_argument);
}

// The message of the std::invalid_argument that reading `j` throws ("" when it reads).
std::string read_error(const json& j) {
  try {
    (void)j.get<ModelParams>();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(ModelParamsJson, RoundTripsEveryEffectField) {
  const ModelParams p = identified();
  const json j = json::parse(json(p).dump(2));
  // Each field written where docs/estimator.md says, and read back to the bit.
  EXPECT_EQ(j["full"]["accel_cross"][0][1].get<double>(), 0.03);
  EXPECT_EQ(j["full"]["accel_cross"][1][0].get<double>(), 0.02);  // rows are the reading axis
  EXPECT_EQ(j["full"]["time_offset"].get<double>(), -0.012);
  EXPECT_NEAR(j["conditions"]["wind_heading_deg"].get<double>(), 0.7 * 180.0 / kPi, 1e-12);
  EXPECT_EQ(j["effects"][1], "wind");
  const ModelParams back = j.get<ModelParams>();
  EXPECT_EQ(back.full.accel_scale, p.full.accel_scale);
  EXPECT_EQ(back.full.accel_cross, p.full.accel_cross);
  EXPECT_EQ(back.full.gyro_bias, p.full.gyro_bias);
  EXPECT_EQ(back.full.time_offset, p.full.time_offset);
  EXPECT_EQ(back.full.wind, p.full.wind);
  EXPECT_EQ(back.full.wind_heading, p.full.wind_heading);
  EXPECT_EQ(back.effects, p.effects);
  EXPECT_EQ(back, p);
  // Degrees alone are enough for the heading too, and disagreeing ones are refused.
  EXPECT_NEAR(json::parse(R"({"full": {"wind_heading_deg": 90}})").get<ModelParams>().full.wind_heading, kPi / 2,
              1e-15);
  json edited = j;
  edited["conditions"]["wind_heading_deg"] = 10.0;
  EXPECT_NE(read_error(edited).find("wind_heading"), std::string::npos);
}

TEST(ModelParamsJson, FilesWithoutTheEffectKeysReadWithTheDefaults) {
  json j = identified();
  for (const char* key : {"accel_scale", "accel_cross", "time_offset"}) j["full"].erase(key);
  j.erase("conditions");
  j.erase("effects");
  const ModelParams p = j.get<ModelParams>();
  EXPECT_EQ(p.full.accel_scale, Eigen::Vector3d::Zero());
  EXPECT_EQ(p.full.accel_cross, Eigen::Matrix3d::Zero());
  EXPECT_EQ(p.full.gyro_bias, Eigen::Vector3d::Zero());
  EXPECT_EQ(p.full.time_offset, 0.0);
  EXPECT_EQ(p.full.wind, Eigen::Vector2d::Zero());
  EXPECT_EQ(p.full.wind_heading, 0.0);
  EXPECT_EQ(p.conditions_flight, "");
  EXPECT_TRUE(p.effects.empty());
  EXPECT_EQ(p.full.drag_linear, identified().full.drag_linear);
}

TEST(ModelParamsJson, KeepsTheFlightsConditionsApartFromTheVehiclesCalibration) {
  const json j = identified();
  for (const char* key : {"wind", "wind_heading", "accel_bias", "gyro_bias"}) {
    EXPECT_FALSE(j["full"].contains(key)) << key;
    EXPECT_TRUE(j["conditions"].contains(key)) << key;
  }
  EXPECT_EQ(j["conditions"]["flight"], "imu:0123456789abcdef");
  EXPECT_EQ(j["conditions"]["wind"][0].get<double>(), 2.5);
  // A file written before conditions were kept apart holds them in "full", and still reads.
  json old = j;
  old.erase("conditions");
  old["full"]["wind"] = {1.0, 2.0};
  old["full"]["accel_bias"] = {0.1, 0.0, 0.0};
  const ModelParams p = old.get<ModelParams>();
  EXPECT_EQ(p.full.wind, Eigen::Vector2d(1.0, 2.0));
  EXPECT_EQ(p.full.accel_bias, Eigen::Vector3d(0.1, 0.0, 0.0));
  EXPECT_EQ(p.conditions_flight, "");
}

TEST(ModelParamsForFlight, AnotherFlightFliesTheVehiclesCalibrationWithoutTheFirstFlightsWind) {
  const ModelParams p = identified();
  std::string left;
  const ModelParams other = for_flight(p, "imu:ffffffffffffffff", &left);
  EXPECT_EQ(other.full.wind, Eigen::Vector2d::Zero());
  EXPECT_TRUE(other.transferred);  // and its filter counts the unknown offset of this flight (config_for)
  EXPECT_EQ(config_for(other).accel_offset_std, 0.45);  // as measured on the flights that validated it
  EXPECT_EQ(config_for(p).accel_offset_std, 0.0);
  EXPECT_EQ(other.full.accel_bias, Eigen::Vector3d::Zero());
  EXPECT_EQ(other.full.gyro_bias, Eigen::Vector3d::Zero());
  // The vehicle's calibration travels whole.
  EXPECT_EQ(other.full.lever_arm, p.full.lever_arm);
  EXPECT_EQ(other.full.mounting, p.full.mounting);
  EXPECT_EQ(other.full.drag_linear, p.full.drag_linear);
  EXPECT_EQ(other.full.drag_quadratic, p.full.drag_quadratic);
  EXPECT_EQ(other.full.accel_scale, p.full.accel_scale);
  EXPECT_EQ(other.full.accel_cross, p.full.accel_cross);
  EXPECT_EQ(other.full.time_offset, p.full.time_offset);
  EXPECT_NE(left.find("wind 2.8 m/s"), std::string::npos) << left;
  // Its own flight keeps them; so does a live flight of parameters that name no flight (an old or edited file).
  EXPECT_EQ(for_flight(p, p.conditions_flight), p);
  ModelParams unnamed = p;
  unnamed.conditions_flight.clear();
  EXPECT_EQ(for_flight(unnamed, ""), unnamed);
  // A live flight ("" : no store has it yet) is never the one the conditions were fitted on.
  EXPECT_EQ(for_flight(p, "").full.wind, Eigen::Vector2d::Zero());
}

TEST(ModelParamsJson, UnknownKeysAreRefusedWithTheirPathAndTheNearestValidKey) {
  const struct {
    const char* pointer;  // where to add the misspelt key
    const char* key;
    const char* path;
    const char* guess;
  } cases[] = {
      {"", "efects", "efects", "effects"},
      {"/paper/x", "alpah", "paper.x.alpah", "paper.x.alpha"},
      {"/paper/y", "muu", "paper.y.muu", "paper.y.mu"},
      {"/full", "acel_scale", "full.acel_scale", "full.accel_scale"},
      {"/full", "wind_heading_degs", "full.wind_heading_degs", "full.wind_heading_deg"},
      {"/identification", "methd", "identification.methd", "identification.method"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.path);
    json j = identified();
    j[json::json_pointer(c.pointer)][c.key] = 1.0;
    const std::string error = read_error(j);
    EXPECT_NE(error.find(std::string("unknown key \"") + c.path + "\""), std::string::npos) << error;
    EXPECT_NE(error.find(std::string("did you mean \"") + c.guess + "\""), std::string::npos) << error;
  }
  // Far from every key: no guess, the valid keys listed instead.
  json j = identified();
  j["full"]["zzzzzzzzzzzz"] = 1.0;
  const std::string error = read_error(j);
  EXPECT_NE(error.find("full.zzzzzzzzzzzz"), std::string::npos) << error;
  EXPECT_EQ(error.find("did you mean"), std::string::npos) << error;
  EXPECT_NE(error.find("accel_cross"), std::string::npos) << error;
  // Free-form maps keep their own keys.
  j = identified();
  j["identification"]["rmse"]["full.x.anything"] = 0.1;
  EXPECT_EQ(read_error(j), "");
}

TEST(ModelParamsJson, WrongTypesAreRefusedNamingTheKeyAndTheTypeExpected) {
  const struct {
    const char* pointer;
    json value;
    const char* path;
    const char* expected;
  } cases[] = {
      {"/full/time_offset", "0.01", "full.time_offset", "a number"},
      {"/full/accel_scale", {0.1, 0.2}, "full.accel_scale", "an array of 3 numbers"},
      {"/full/accel_cross", {0.0, 0.1, 0.2}, "full.accel_cross", "an array of 3 rows of 3 numbers"},
      {"/full/wind", true, "full.wind", "an array of 2 numbers"},
      {"/paper/x/r", json::array(), "paper.x.r", "a number"},
      {"/identification/seed", -3, "identification.seed", "an unsigned integer"},
      {"/identification/method", 5, "identification.method", "a string"},
      {"/effects", "wind", "effects", "an array of effect names"},
      {"/full", 3, "full", "an object"},
      {"/version", "1", "version", "an integer"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.path);
    json j = identified();
    j[json::json_pointer(c.pointer)] = c.value;
    const std::string error = read_error(j);
    EXPECT_NE(error.find(std::string(c.path) + ": expected " + c.expected), std::string::npos) << error;
  }
}

// The effects are what the model was built from, kept as named: what each adds live is in `full`. A model with an
// effect the live estimator cannot run is refused, with the reason diagnose wrote beside it.
TEST(ModelParamsJson, AModelWithAnEffectTheLiveEstimatorCannotRunIsRefusedWithItsReason) {
  json j = identified();
  j["effects"] = {"linear_drag", "an_effect_of_a_later_diagnose"};
  EXPECT_EQ(j.get<ModelParams>().effects, (std::vector<std::string>{"linear_drag", "an_effect_of_a_later_diagnose"}));
  j["effects"] = {"linear_drag", 3};
  EXPECT_NE(read_error(j).find("effects[]: expected an effect name (a string)"), std::string::npos) << read_error(j);

  j["effects"] = {"linear_drag", "vibration"};
  j["not_live"] = {{"vibration", "live, vibration is measurement noise: re-run diagnose with --lowpass"}};
  const std::string error = read_error(j);
  EXPECT_NE(error.find("not_live.vibration: the live estimator cannot run it: live, vibration is measurement noise"),
            std::string::npos)
      << error;
  EXPECT_EQ(error.find('\n'), std::string::npos) << error;  // one line
  j["not_live"] = json::object();
  EXPECT_EQ(j.get<ModelParams>().effects, (std::vector<std::string>{"linear_drag", "vibration"}));
  j["not_live"] = {{"vibration", 1}};
  EXPECT_NE(read_error(j).find("not_live.vibration: expected the reason (a string)"), std::string::npos)
      << read_error(j);
}

TEST(ModelParamsJson, RefusesEffectParametersOutOfRange) {
  json j = identified();
  j["full"]["time_offset"] = 0.3;
  EXPECT_NE(read_error(j).find("time_offset"), std::string::npos);
  j = identified();
  j["full"]["accel_scale"] = {-1.0, 0.0, 0.0};
  EXPECT_NE(read_error(j).find("accel_scale"), std::string::npos);
  j = identified();
  j["full"]["accel_cross"][2][2] = 0.01;
  EXPECT_NE(read_error(j).find("accel_cross"), std::string::npos);
}

// The file functions every command shares: what save_params() writes, load_params() reads back equal.
TEST(ParamsFile, SavedParametersLoadBackEqual) {
  const test::TempDir dir;
  const ModelParams p = identified();
  save_params(dir / "params.json", p);
  EXPECT_EQ(load_params(dir / "params.json"), p);
}

TEST(ParamsFile, ErrorsNameTheFile) {
  const test::TempDir dir;
  try {
    (void)load_params(dir / "missing.json");
    FAIL() << "a missing file was read";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("missing.json: cannot read the parameters file"), std::string::npos)
        << e.what();
  }
  std::ofstream(dir / "bad.json") << R"({"full": {"drag_linaer": [0.3, 0.4]}})";
  try {
    (void)load_params(dir / "bad.json");
    FAIL() << "an unknown key was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("bad.json is not valid PARAMS.json: "), std::string::npos) << e.what();
  }
  EXPECT_THROW((void)parse_params("{", "run 3"), std::invalid_argument);
}

}  // namespace
}  // namespace imubridge::estimator
