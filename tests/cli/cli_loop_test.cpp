// The loop closed into the live estimator, as a user runs it: diagnose a simulated flight that hides a wind and an
// accelerometer lagging its gyro, write the final model with --out, and run it: evaluate and replay estimate with
// exactly that model, and its velocity error is what the report claims.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/support/run_command.hpp"

namespace imubridge::test {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

class LoopToEstimator : public ::testing::Test {
 protected:
  static inline fs::path dir_;
  static inline std::string db_;
  static inline json report_;
  static inline CommandResult diagnosed_;

  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / ("imubridge_loop_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    db_ = (dir_ / "flight.db").string();
    const CommandResult sim = run_imubridge("sim --scenario paper --seed 11 --duration 40 --effect wind=3,1.5 "
                                            "--effect time_offset=0.02 --db " + db_);
    ASSERT_EQ(sim.exit_code, 0) << sim.err;
    diagnosed_ = run_imubridge("diagnose --db " + db_ + " --session 1 --train 0:60% --validate 60%: --out " +
                               (dir_ / "final.json").string() + " --report " + (dir_ / "report").string());
    ASSERT_EQ(diagnosed_.exit_code, 0) << diagnosed_.err;
    report_ = json::parse(slurp(dir_ / "report" / "report.json"));
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }

  static double claimed(const json& fit) { return fit["velocity_rmse_m_s"]["validation"]["horizontal"].get<double>(); }
};

TEST_F(LoopToEstimator, TheReportSaysWhatEachStepDidToTheVelocity) {
  const json& j = report_;
  ASSERT_FALSE(j["steps"].empty());
  for (const json& step : j["steps"]) {
    ASSERT_TRUE(step["velocity_rmse_m_s"].is_object()) << step.dump();
    for (const char* axis : {"x", "y", "horizontal"}) {
      EXPECT_GT(step["velocity_rmse_m_s"]["train"][axis].get<double>(), 0.0);
      EXPECT_GT(step["velocity_rmse_m_s"]["validation"][axis].get<double>(), 0.0);
    }
  }
  EXPECT_GT(j["zero_velocity_rmse_m_s"]["validation"]["horizontal"].get<double>(), 0.0);
  EXPECT_NE(j["summary"].get<std::string>().find("velocity RMSE"), std::string::npos) << j["summary"];
  EXPECT_NE(diagnosed_.out.find("summary: velocity RMSE"), std::string::npos) << diagnosed_.out;
  // The hidden effects are what the loop added.
  const json effects = j["final"]["effects"];
  EXPECT_NE(std::find(effects.begin(), effects.end(), "wind"), effects.end()) << effects.dump();
  EXPECT_NE(std::find(effects.begin(), effects.end(), "time_offset"), effects.end()) << effects.dump();
}

TEST_F(LoopToEstimator, EveryCandidateLeftOutNamesTheRuleThatStoppedIt) {
  ASSERT_FALSE(report_["last_candidates"].empty());
  for (const json& c : report_["last_candidates"]) {
    if (!c["skipped"].get<std::string>().empty()) continue;
    const std::string rule = c["rejected_by"];
    EXPECT_TRUE(rule.rfind("minimum-gain rule", 0) == 0 || rule.rfind("F-test: p = ", 0) == 0) << c.dump();
    EXPECT_FALSE(c["significant"].get<bool>());
  }
  EXPECT_NE(diagnosed_.out.find("stopped: the best candidate"), std::string::npos) << diagnosed_.out;
}

TEST_F(LoopToEstimator, EvaluateWithThePrintedModelCutsTheVelocityErrorByTheClaimedFactor) {
  const double before = claimed(report_["base"]), after = claimed(report_["final"]);
  EXPECT_LT(after, before / 1.5) << "the loop claims too little to be worth testing: " << before << " -> " << after;
  const json params = json::parse(slurp(dir_ / "final.json"));
  EXPECT_EQ(params["effects"], report_["final"]["effects"]);
  const json window = report_["validation_window"];
  const CommandResult e = run_imubridge("evaluate --db " + db_ + " --session 1 --params " +
                                        (dir_ / "final.json").string() + " --window " +
                                        std::to_string(window["start"].get<double>()) + ":");
  ASSERT_EQ(e.exit_code, 0) << e.err;
  const double measured = json::parse(e.out)["rmse_m_s"]["estimator"]["horizontal"].get<double>();
  // The same estimator on the same samples: the factor measured is the factor claimed.
  EXPECT_NEAR(measured, after, 0.02 * after);
  EXPECT_LT(measured, before / 1.5);
}

TEST_F(LoopToEstimator, ReplayRunsTheModelTheLoopEndedWith) {
  const CommandResult r =
      run_imubridge("replay --db " + db_ + " --session 1 --params " + (dir_ / "final.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string run = r.out.substr(r.out.find_last_of('\n', r.out.size() - 2) + 1);  // its last line: the run
  const CommandResult estimates =
      run_imubridge("export --db " + db_ + " --session 1 --what estimates --run " + run.substr(0, run.size() - 1));
  ASSERT_EQ(estimates.exit_code, 0) << estimates.err;
  EXPECT_GT(count_lines(estimates.out), 1000) << "replay stored too few estimates";
}

}  // namespace
}  // namespace imubridge::test
