// `imubridge diagnose` as a user runs it, on a short session recorded by `imubridge sim`: the report's fields and
// the exit codes for bad input.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/support/run_command.hpp"

namespace imubridge::test {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

class DiagnoseCommand : public ::testing::Test {
 protected:
  static inline fs::path dir_;
  static inline std::string db_;

  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / ("imubridge_diagnose_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    db_ = (dir_ / "flight.db").string();
    // The paper's flight with an accelerometer lagging the gyro by 10 ms: something to find (session 1); two more
    // flights of the same vehicle (sessions 2 and 3).
    for (const char* seed : {"3", "4", "5"}) {
      const CommandResult r = run_imubridge(std::string("sim --scenario paper --seed ") + seed +
                                            " --duration 30 --effect time_offset=0.01 --db " + db_);
      ASSERT_EQ(r.exit_code, 0) << r.err;
    }
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }

  static CommandResult diagnose(const std::string& args) { return run_imubridge("diagnose --db " + db_ + " " + args); }

  static void expect_error(const CommandResult& r, const std::string& says) {
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_EQ(count_lines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(says), std::string::npos) << r.err;
  }
};

TEST_F(DiagnoseCommand, WritesTheReport) {
  const fs::path report = dir_ / "report";
  const CommandResult r =
      diagnose("--session 1 --train 0:20 --validate 20:30 --max-steps 1 --report " + report.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("step 1: + time_offset"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("velocity RMSE"), std::string::npos) << r.out;    // the user's units, beside m/s^2
  EXPECT_EQ(r.err.find("covariance_impl"), std::string::npos) << r.err;  // no raw Ceres log lines
  ASSERT_TRUE(fs::exists(report / "report.html"));
  const json j = json::parse(slurp(report / "report.json"));
  EXPECT_EQ(j["velocity_source"], "reference");  // the simulated session has one
  EXPECT_GT(j["base"]["rmse_train"].get<double>(), 0.0);
  EXPECT_GT(j["base"]["rmse_validation"].get<double>(), 0.0);
  ASSERT_EQ(j["steps"].size(), 1u);
  const json& step = j["steps"][0];
  EXPECT_EQ(step["effect"], "time_offset");
  EXPECT_EQ(step["params"][0]["name"], "tau");
  EXPECT_NEAR(step["params"][0]["value"].get<double>(), 0.01, 0.001);
  EXPECT_LT(step["rmse_validation"].get<double>(), 0.5 * j["base"]["rmse_validation"].get<double>());
  EXPECT_GT(step["rmse_train"].get<double>(), 0.0);
  EXPECT_TRUE(j.contains("final"));
  EXPECT_TRUE(j["residual_white"].is_boolean());
  ASSERT_TRUE(j["unexplained"].is_array());
  for (const json& u : j["unexplained"]) EXPECT_TRUE(u.contains("kind")) << u.dump();
}

TEST_F(DiagnoseCommand, ACandidateBeyondThePlausibilityTableIsRefusedWithItsReason) {
  // The flight's 10-ms offset is found when allowed (WritesTheReport); with a 1-ms limit it is implausible.
  const fs::path report = dir_ / "limited";
  const CommandResult r = diagnose(
      "--session 1 --train 0:20 --validate 20:30 --max-steps 1 --limit time_offset=0.001 "
      "--report " +
      report.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json j = json::parse(slurp(report / "report.json"));
  const json& candidates = j["steps"].empty() ? j["last_candidates"] : j["steps"][0]["candidates"];
  bool refused = false;
  for (const json& c : candidates) {
    if (c["effect"] != "time_offset") continue;
    const std::string why = c["skipped"];
    refused = why.rfind("implausible", 0) == 0 && why.find("--limit time_offset") != std::string::npos;
    EXPECT_TRUE(refused) << why;
  }
  EXPECT_TRUE(refused);
  for (const json& step : j["steps"]) EXPECT_NE(step["effect"], "time_offset");
  EXPECT_EQ(diagnose("--session 1 --limit wingspan=2 --report " + report.string()).exit_code, 2);
}

TEST_F(DiagnoseCommand, ImuAloneWhenAsked) {
  const fs::path report = dir_ / "imu";
  const CommandResult r =
      diagnose("--session 1 --axis x --velocity imu --train 0:20 --max-steps 0 --report " + report.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json j = json::parse(slurp(report / "report.json"));
  EXPECT_EQ(j["velocity_source"], "imu");
  EXPECT_EQ(j["axes"], json::array({"x"}));
  EXPECT_TRUE(j["steps"].empty());
}

TEST_F(DiagnoseCommand, SeveralFlightsFitTogetherAndValidateOnAnother) {
  const fs::path params = dir_ / "set.json";
  const CommandResult r = diagnose("--session 1,2 --validate-session 3 --max-steps 1 --out " + params.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("step 1: + time_offset"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("session 2 fits"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("session 3 validates"), std::string::npos) << r.out;
  const json p = json::parse(slurp(params));
  EXPECT_NEAR(p["full"]["time_offset"].get<double>(), 0.01, 0.001);
  EXPECT_TRUE(p["conditions"]["flight"].get<std::string>().starts_with("flights:imu:")) << p["conditions"];

  expect_error(diagnose("--session 1,2"), "--validate-session");
  expect_error(diagnose("--session 1 --validate-session 1"), "both fits and validates");
  expect_error(diagnose("--session 1,2 --validate-session 3 --velocity imu"), "takes one session");
}

TEST_F(DiagnoseCommand, BadInputIsOneLineAndExitCode2) {
  const std::string report = " --report " + (dir_ / "bad").string();
  expect_error(diagnose("--session 1 --axis z" + report), "unknown axis");
  expect_error(diagnose("--session 1 --model huge" + report), "unknown model");
  expect_error(diagnose("--session 1 --velocity gps" + report), "unknown velocity source");
  expect_error(diagnose("--session 1 --ignore-band 40:30" + report), "bad band");
  expect_error(diagnose("--session 1 --train 100:200" + report), "holds no data");
  expect_error(diagnose("--session 9" + report), "no session 9");
}

// A user who wants the model only needs no report directory (issue 28).
TEST_F(DiagnoseCommand, OutAloneWritesTheModelWithoutAReport) {
  const fs::path params = dir_ / "model_only" / "PARAMS.json";
  fs::create_directories(params.parent_path());
  const CommandResult r =
      diagnose("--session 1 --axis x --train 0:20 --validate 20:30 --max-steps 0 --out " + params.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json model = json::parse(slurp(params));
  EXPECT_TRUE(model.is_object() && !model.empty()) << model.dump();
  EXPECT_EQ(r.out.find("report.json"), std::string::npos) << r.out;
  EXPECT_EQ(std::distance(fs::directory_iterator(params.parent_path()), fs::directory_iterator()), 1)
      << "PARAMS.json alone, no report and no temporary file";
}

}  // namespace
}  // namespace imubridge::test
