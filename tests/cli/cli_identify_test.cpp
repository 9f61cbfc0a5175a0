// `imubridge identify` and `imubridge evaluate` as a user runs them, on a session recorded by `imubridge sim`.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "estimator/params.hpp"
#include "sim/scenario.hpp"
#include "store/store.hpp"
#include "tests/support/run_command.hpp"

namespace imubridge::test {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr double kDeg = 3.14159265358979323846 / 180.0;

// One 60-s flight of the paper's scenario, recorded once for the whole suite (session 1), a session without a
// reference trajectory (session 2), written through the store as an importer without ground truth would, and two
// more flights of the scenario with other seeds (sessions 3 and 4).
class IdentifyCommand : public ::testing::Test {
 protected:
  static inline fs::path dir_;
  static inline std::string db_;

  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / ("imubridge_identify_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    db_ = (dir_ / "flights.db").string();
    const CommandResult r = run_imubridge("sim --scenario paper --seed 1 --db " + db_);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    {  // closed before the next writer starts
      store::Store store(db_);
      const std::int64_t session = store.begin_session({.kind = "import"});
      const std::int64_t link = store.add_link(session, "imu0", "imubridge", "test");
      for (int k = 0; k < 400; ++k) {
        protocol::Sample s;
        s.link_id = link;
        s.device_time_us = 5000 * k;
        s.recv_mono_ns = 5'000'000 * static_cast<std::int64_t>(k);
        s.accel = {0.0, 0.0, -9.8};
        store.append_sample(session, s);
      }
    }
    for (const char* seed : {"2", "3"}) {
      const CommandResult more = run_imubridge(std::string("sim --scenario paper --seed ") + seed + " --db " + db_);
      ASSERT_EQ(more.exit_code, 0) << more.err;
    }
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }

  static std::string out(const std::string& name) { return (dir_ / name).string(); }
  static json read_json(const std::string& path) { return json::parse(slurp(path)); }
  static CommandResult identify(const std::string& args) { return run_imubridge("identify --db " + db_ + " " + args); }

  // A usage or data error: exit code `code` and one line on stderr that names the problem.
  static void expect_error(const CommandResult& r, int code, const std::string& says) {
    EXPECT_EQ(r.exit_code, code) << r.err;
    EXPECT_EQ(count_lines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(says), std::string::npos) << r.err;
  }
};

TEST_F(IdentifyCommand, LmWritesThePapersParametersWithStandardErrors) {
  const CommandResult r =
      identify("--session 1 --model paper --method lm --velocity reference --out " + out("lm.json"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json p = read_json(out("lm.json"));
  const json& x = p["paper"]["x"];
  EXPECT_NEAR(x["r"].get<double>(), sim::kPaperR, 0.02 * sim::kPaperR);
  EXPECT_NEAR(x["beta_deg"].get<double>(), 85.12, 1.0);
  EXPECT_NEAR(x["alpha_deg"].get<double>(), -0.3, 0.1);
  EXPECT_NEAR(x["mu"].get<double>(), sim::kPaperMu, 0.05 * sim::kPaperMu);
  const json& id = p["identification"];
  EXPECT_EQ(id["method"], "lm");
  EXPECT_EQ(id["fit_windows"], json::parse("[[0.0, 33.0]]"));
  EXPECT_EQ(id["validation_windows"][0][0], 33.0);
  EXPECT_NEAR(id["validation_windows"][0][1].get<double>(), 60.0, 1e-9);
  for (const char* key : {"paper.x.r", "paper.x.beta", "paper.x.alpha", "paper.x.mu", "paper.y.r"})
    EXPECT_GT(id["std_errors"][key].get<double>(), 0.0) << key;
  for (const char* key : {"paper.x.fit", "paper.x.validation", "paper.y.fit", "paper.y.validation"})
    EXPECT_GT(id["rmse"][key].get<double>(), 0.0) << key;
  // What `run` and `replay` will read: the same file through estimator/params.hpp, the live model filled in.
  const auto params = p.get<estimator::ModelParams>();
  EXPECT_GT(params.full.drag_quadratic.x(), 0.0);
  EXPECT_NEAR(params.full.lever_arm.z(), -sim::kPaperR * std::sin(sim::kPaperBeta), 0.003);
  // The summary for people: degrees, the correlation matrix, the wall time.
  EXPECT_NE(r.err.find("beta"), std::string::npos);
  EXPECT_NE(r.err.find("deg"), std::string::npos);
  EXPECT_NE(r.err.find("correlation"), std::string::npos);
  EXPECT_NE(r.err.find("wall time"), std::string::npos);
}

TEST_F(IdentifyCommand, GaWritesItsConvergenceCurveBesideTheParams) {
  const CommandResult r = identify(
      "--session 1 --method ga --seed 5 --population 30 --generations 60 --mutation 0.2 "
      "--train 0:20 --validate 20:60 --out " +
      out("ga.json"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json id = read_json(out("ga.json"))["identification"];
  EXPECT_EQ(id["method"], "ga");
  EXPECT_EQ(id["seed"], 5);
  EXPECT_EQ(id["fit_windows"], json::parse("[[0.0, 20.0]]"));
  std::istringstream curve(slurp(out("ga.convergence.csv")));
  std::string line;
  std::getline(curve, line);
  EXPECT_EQ(line, "generation,paper.x,paper.y");
  std::vector<double> best;
  while (std::getline(curve, line)) best.push_back(std::stod(line.substr(line.find(',') + 1)));
  ASSERT_EQ(best.size(), 61u);
  for (std::size_t g = 1; g < best.size(); ++g) EXPECT_LE(best[g], best[g - 1]);
  // The same seed again: the same file, byte for byte.
  ASSERT_EQ(identify("--session 1 --method ga --seed 5 --population 30 --generations 60 --mutation 0.2 "
                     "--train 0:20 --validate 20:60 --out " +
                     out("ga2.json"))
                .exit_code,
            0);
  EXPECT_EQ(slurp(out("ga.json")), slurp(out("ga2.json")));
}

TEST_F(IdentifyCommand, EvaluateScoresTheEstimatorAgainstTheReference) {
  ASSERT_EQ(identify("--session 1 --velocity reference --out " + out("eval.json")).exit_code, 0);
  const CommandResult r =
      run_imubridge("evaluate --db " + db_ + " --session 1 --params " + out("eval.json") + " --window 10:60");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json e = json::parse(r.out);
  EXPECT_EQ(e["samples"], 10000 - 2);  // the last two wait for the differentiator's window (delay (5 - 1) / 2)
  const json& rmse = e["rmse_m_s"];
  for (const char* source : {"estimator", "raw_inversion", "eq12", "zero"})
    EXPECT_GT(rmse[source]["horizontal"].get<double>(), 0.0) << source;
  EXPECT_LT(rmse["estimator"]["horizontal"], rmse["zero"]["horizontal"]);
  EXPECT_LT(rmse["estimator"]["horizontal"], rmse["raw_inversion"]["horizontal"]);
  EXPECT_LT(rmse["estimator"]["horizontal"], rmse["eq12"]["horizontal"]);
  // The filter's error splits into its mean over the window and what is left about it: squares add up per axis.
  for (int axis = 0; axis < 2; ++axis) {
    const char* name = axis == 0 ? "x" : "y";
    const double whole = rmse["estimator"][name], left = rmse["estimator_constant_known"][name];
    const double mean = e["estimator_mean_error_m_s"][axis];
    EXPECT_LE(left, whole);
    EXPECT_NEAR(whole * whole, left * left + mean * mean, 1e-9 + 1e-9 * whole * whole) << axis;
  }
}

TEST_F(IdentifyCommand, EvaluateScoresOneCalibrationOverSeveralFlights) {
  ASSERT_EQ(identify("--session 1 --velocity reference --out " + out("fleet.json")).exit_code, 0);
  const std::string evaluate = "evaluate --db " + db_ + " --params " + out("fleet.json") + " --window 10:60 ";
  const CommandResult r = run_imubridge(evaluate + "--session 1,3");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json e = json::parse(r.out);
  ASSERT_EQ(e["flights"].size(), 2u);
  EXPECT_EQ(e["flights"][0]["session"], 1);
  EXPECT_EQ(e["flights"][1]["session"], 3);
  const json& summary = e["summary"];
  EXPECT_EQ(summary["flights_scored"], 2);
  EXPECT_EQ(summary["estimator"]["flights_worse_than_zero"], 0);
  // Each flight's estimator against zero velocity beyond chance, both ways; these fly far better than it.
  EXPECT_EQ(summary["estimator"]["flights_clearly_better_than_zero"], 2);
  EXPECT_EQ(summary["estimator"]["flights_clearly_worse_than_zero"], 0);
  for (const json& f : e["flights"]) {
    EXPECT_LT(f["estimator_versus_zero_p"]["better"].get<double>(), 0.01);
    EXPECT_EQ(f["estimator_versus_zero_p"]["worse"].get<double>(), 1.0);
  }
  // The median of two is their mean.
  const auto horizontal = [&e](int f, const char* source) {
    return e["flights"][f]["rmse_m_s"][source]["horizontal"].get<double>();
  };
  EXPECT_NEAR(summary["estimator"]["median_rmse_m_s"].get<double>(),
              0.5 * (horizontal(0, "estimator") + horizontal(1, "estimator")), 1e-9);
  EXPECT_LT(summary["estimator"]["median_ratio_to_zero"].get<double>(), 1.0);
  EXPECT_NE(r.err.find("estimator: median"), std::string::npos) << r.err;

  // The anchor alone, without a PARAMS.json: zero velocity beside it.
  const CommandResult anchor = run_imubridge(
      "evaluate --db " + db_ + " --window 10:60 --session 1,3 --baseline-session 4 --baseline-train 0:60");
  ASSERT_EQ(anchor.exit_code, 0) << anchor.err;
  const json a = json::parse(anchor.out);
  EXPECT_FALSE(a["summary"].contains("estimator"));
  // On this flight the lever arm's terms swamp a two-parameter line, whose slopes are then noise: the anchor reads no
  // drag and flies at zero velocity, never worse than it (it divided by the noise before: far worse, on both).
  EXPECT_EQ(a["summary"]["least_squares_smoothed"]["flights_worse_than_zero"], 0);
  EXPECT_NE(a["flights"][0]["least_squares"]["note"].get<std::string>().find("no drag read"), std::string::npos);
  EXPECT_NEAR(a["flights"][1]["rmse_m_s"]["zero"]["horizontal"].get<double>(), horizontal(1, "zero"), 0.05);
  expect_error(run_imubridge("evaluate --db " + db_ + " --session 1"), 2, "nothing to score");

  // A flight that cannot be scored is named in its row and in the exit status; the others are still scored.
  const CommandResult partly = run_imubridge(evaluate + "--session 1-3");
  EXPECT_EQ(partly.exit_code, 1) << partly.err;
  const json p = json::parse(partly.out);
  ASSERT_EQ(p["flights"].size(), 3u);
  EXPECT_NE(p["flights"][1]["error"].get<std::string>().find("no reference trajectory"), std::string::npos);
  EXPECT_EQ(p["summary"]["flights_scored"], 2);
  EXPECT_EQ(p["summary"]["flights_not_scored"], 1);

  expect_error(run_imubridge(evaluate + "--session 3-1"), 2, "invalid --session");
  expect_error(run_imubridge(evaluate + "--session 1,x"), 2, "invalid --session");
}

TEST_F(IdentifyCommand, EvaluateCarriesTheLeastSquaresAnchorFromItsOwnSession) {
  ASSERT_EQ(identify("--session 1 --velocity reference --out " + out("anchor.json")).exit_code, 0);
  const std::string evaluate = "evaluate --db " + db_ + " --params " + out("anchor.json") + " --window 10:60 ";
  const CommandResult own = run_imubridge(evaluate + "--session 3 --baseline-train 0:60");
  ASSERT_EQ(own.exit_code, 0) << own.err;
  const CommandResult carried = run_imubridge(evaluate + "--session 3 --baseline-train 0:60 --baseline-session 1");
  ASSERT_EQ(carried.exit_code, 0) << carried.err;
  const json o = json::parse(own.out), c = json::parse(carried.out);
  EXPECT_EQ(o["least_squares"]["train_sessions"], json::array({3}));
  EXPECT_EQ(c["least_squares"]["train_sessions"], json::array({1}));
  // An anchor that cannot be fitted is said, once and in each flight's report; the model is still scored.
  const CommandResult unfit = run_imubridge(evaluate + "--session 3,4 --baseline-train 500:600 --baseline-session 1");
  ASSERT_EQ(unfit.exit_code, 0) << unfit.err;
  EXPECT_NE(unfit.err.find("warning: the least-squares anchor: no 0.1-s block inside the training window"),
            std::string::npos)
      << unfit.err;
  const json u = json::parse(unfit.out);
  EXPECT_TRUE(u["flights"][0].contains("least_squares_error"));
  EXPECT_EQ(u["summary"]["estimator"]["flights_worse_than_zero"], 0);
  // Fitted over two flights together: one line, neither flight's own.
  const CommandResult pooled = run_imubridge(evaluate + "--session 3 --baseline-train 0:60 --baseline-session 1,4");
  ASSERT_EQ(pooled.exit_code, 0) << pooled.err;
  const json p = json::parse(pooled.out);
  EXPECT_EQ(p["least_squares"]["train_sessions"], json::array({1, 4}));
  EXPECT_EQ(p["least_squares"]["train_windows"].size(), 2u);
  EXPECT_NE(p["least_squares"]["b"], c["least_squares"]["b"]);
  EXPECT_NE(o["least_squares"]["b"], c["least_squares"]["b"]);
  for (const json* e : {&o, &c}) {
    const json& rmse = (*e)["rmse_m_s"];
    EXPECT_GT(rmse["least_squares_means"]["horizontal"].get<double>(), 0.0);
    // The paper's slow flight reads no drag above its lever arm's terms (slopes of 0.03 +- 0.09 1/s): the anchor flies
    // it at zero velocity and says so, where dividing by those slopes gave 5.4 m/s against zero velocity's 0.57
    // (velocity_anchor_test has anchors that read a drag).
    EXPECT_EQ((*e)["least_squares"]["k"], json::array({0.0, 0.0}));
    EXPECT_NE((*e)["least_squares"]["note"].get<std::string>().find("no drag read on x"), std::string::npos);
    EXPECT_DOUBLE_EQ(rmse["least_squares_smoothed"]["horizontal"].get<double>(),
                     rmse["least_squares_means"]["horizontal"].get<double>());
    EXPECT_EQ((*e)["least_squares"]["blocks_scored"], 500);
  }
}

// A bias no accelerometer has, with every other value plausible, is the fit trading the bias against the mounting's
// tilt: the vehicle is fitted again with the bias held at zero and written, with a warning, not refused.
TEST_F(IdentifyCommand, ABiasBeyondThePlausibilityTableIsHeldAtZeroAndTheCalibrationWritten) {
  // The simulated IMU has no bias; the fitted one is small but not zero, and a table that allows 1e-6 m/s^2 makes it
  // implausible.
  const std::string tight = " --session 1 --model full --velocity reference --limit accel_bias=0.000001";
  const CommandResult r = identify(tight + " --out " + out("bias-held.json"));
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("warning: the fitted accelerometer bias was implausible"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("held at zero"), std::string::npos) << r.out;
  const json p = read_json(out("bias-held.json"));
  EXPECT_TRUE(p.get<estimator::ModelParams>().full.accel_bias.isZero());
  for (const auto& [key, value] : p["identification"]["std_errors"].items())
    EXPECT_EQ(key.find("accel_bias"), std::string::npos) << key << " was fitted";

  // Anything else beyond the table is still refused: only the bias is held.
  const CommandResult lever = identify(tight + " --limit lever_arm=0.01 --out " + out("lever-refused.json"));
  EXPECT_EQ(lever.exit_code, 1) << lever.out << lever.err;
  EXPECT_NE(lever.out.find("refused: implausible: lever arm"), std::string::npos) << lever.out;
  EXPECT_FALSE(fs::exists(out("lever-refused.json")));
  // Its summary says so and nowhere claims the file was written.
  EXPECT_NE(lever.err.find("lever-refused.json is not written"), std::string::npos) << lever.err;
  EXPECT_EQ(lever.err.find("wrote"), std::string::npos) << lever.err;
}

TEST_F(IdentifyCommand, FitsOneCalibrationOverSeveralFlightsAndValidatesItOnOthers) {
  // The velocity defaults to the reference, which every flight of the set has.
  const CommandResult r = identify("--session 1,3 --validate-session 4 --model paper --out " + out("set.json"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("velocity reference"), std::string::npos) << r.err;
  const json p = read_json(out("set.json"));
  for (const char* axis : {"x", "y"}) {
    EXPECT_NEAR(p["paper"][axis]["r"].get<double>(), sim::kPaperR, 0.02 * sim::kPaperR) << axis;
    EXPECT_NEAR(p["paper"][axis]["mu"].get<double>(), sim::kPaperMu, 0.05 * sim::kPaperMu) << axis;
  }
  // Fitted on two whole 60-s flights (with the gap between them), validated on the third.
  const json& id = p["identification"];
  EXPECT_NEAR(id["fit_windows"][0][0].get<double>(), 0.0, 1e-9);
  EXPECT_GT(id["validation_windows"][0][0].get<double>(), 120.0);
  // The conditions belong to no one flight of the set: named by the set, they fly on none of them.
  const std::string flight = p["conditions"]["flight"];
  EXPECT_TRUE(flight.starts_with("flights:imu:")) << flight;
  EXPECT_EQ(std::count(flight.begin(), flight.end(), ','), 2) << flight;
  EXPECT_NE(r.err.find("session 3 fits"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("session 4 validates"), std::string::npos) << r.err;
  // The offset a new flight carries, measured on the validating flight (it has a reference) for the live filter.
  EXPECT_NE(r.err.find("measured on the 1 validating flights"), std::string::npos) << r.err;
  EXPECT_GE(id["transfer_offset_std"].get<double>(), 0.0);

  const std::string args = " --velocity reference --out " + out("set-bad.json");
  expect_error(identify("--session 1,3" + args), 2, "--validate-session");
  expect_error(identify("--session 1,3 --validate-session 3" + args), 2, "both fits and validates");
  expect_error(identify("--session 1 --validate-session 2" + args), 2, "no reference trajectory");
  expect_error(identify("--session 1,3 --validate-session 4 --velocity eq12 --out " + out("set-bad.json")), 2,
               "takes one session");
  expect_error(identify("--session 1,3 --validate-session 4 --train 0:4" + args), 2, "the fitting flights hold 8.0 s");
  EXPECT_FALSE(fs::exists(out("set-bad.json")));
}

TEST_F(IdentifyCommand, BadInputGivesOneLineAndAnExitCode) {
  const std::string p = " --out " + out("bad.json");
  expect_error(identify("--session 1 --train 40:20" + p), 2, "bad window");
  expect_error(identify("--session 1 --train 100:200" + p), 2, "holds no data");
  expect_error(identify("--session 1 --validate 70:" + p), 2, "validation window");
  expect_error(identify("--session 9" + p), 2, "no session 9");
  expect_error(identify("--session 1 --method sa" + p), 2, "ga, lm, ga+lm");
  expect_error(identify("--session 1 --hold mounting" + p), 2, "--model full");
  expect_error(identify("--session 1 --model full --hold wings" + p), 2, "unknown block");
  expect_error(identify("--session 1 --model full --hold lever_arm --hold mounting --hold drag_linear "
                        "--hold drag_quadratic --hold accel_bias" +
                        p),
               2, "nothing to identify");
  expect_error(identify("--session 1 --method ga --population 1" + p), 2, "population");
  expect_error(identify("--session 1 --train 0:0.01" + p), 2,
               "holds 0.0 s of data; identifying the drag needs at least 10 s");
  expect_error(identify("--session 2 --velocity reference" + p), 2, "no reference trajectory");
  // Without a reference the velocity defaults to the filter's, which the GA cannot fit: refused, not run by LM.
  expect_error(identify("--session 2 --method ga" + p), 2, "--velocity eq12");
  expect_error(run_imubridge("identify --db " + out("missing.db") + " --session 1" + p), 1, "missing.db");
  EXPECT_FALSE(fs::exists(out("bad.json")));

  ASSERT_EQ(identify("--session 1 --out " + out("ok.json")).exit_code, 0);
  expect_error(run_imubridge("evaluate --db " + db_ + " --session 2 --params " + out("ok.json")), 2,
               "no reference trajectory");
  std::ofstream(out("broken.json")) << "{\"paper\": {\"x\": {\"r\": -1}}}";
  expect_error(run_imubridge("evaluate --db " + db_ + " --session 1 --params " + out("broken.json")), 2, "broken.json");
  std::ofstream(out("nodrag.json")) << "{}";
  expect_error(run_imubridge("evaluate --db " + db_ + " --session 1 --params " + out("nodrag.json")), 2, "drag");
}

}  // namespace
}  // namespace imubridge::test
