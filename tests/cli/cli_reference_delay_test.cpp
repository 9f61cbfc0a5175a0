// The reference as users have it: `imubridge sim --effect reference_delay=...` records a late, slow reference;
// `evaluate` and `identify` estimate its delay, say it, shift the reference by it and record it, or take it as
// declared with --reference-delay; a flight that cannot tell says so and shifts nothing.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <regex>
#include <string>

#include "estimator/params.hpp"
#include "tests/support/paper_params.hpp"
#include "tests/support/run_command.hpp"

namespace imubridge::test {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// Sessions 1-3 of one store: a 0.2-s late reference at 10 Hz, one on time, and a hover with the late reference.
class ReferenceDelayCommands : public ::testing::Test {
 protected:
  static inline fs::path dir_;
  static inline std::string db_;

  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / ("imubridge_refdelay_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    db_ = (dir_ / "flights.db").string();
    for (const std::string& flight :
         {std::string("--scenario paper --duration 40 --effect reference_delay=0.2 --effect reference_rate=10"),
          std::string("--scenario paper --duration 40"),
          std::string("--scenario hover --duration 20 --effect reference_delay=0.2 --effect reference_rate=10")}) {
      const CommandResult r = run_imubridge("sim --seed 2 " + flight + " --db " + db_);
      ASSERT_EQ(r.exit_code, 0) << r.err;
    }
    estimator::save_params(dir_ / "paper.json", paper_params());  // the simulated vehicle's own model
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }

  static CommandResult evaluate(int session, const std::string& extra = "") {
    return run_imubridge("evaluate --db " + db_ + " --session " + std::to_string(session) + " --params " +
                         (dir_ / "paper.json").string() + " " + extra);
  }
  // The delay the line "reference delay: D s (correlation C), ..." gives, or NaN without one.
  static double said_delay(const std::string& err) {
    std::smatch m;
    if (!std::regex_search(err, m, std::regex("reference delay: (-?[0-9.]+) s \\(correlation"))) return std::nan("");
    return std::stod(m[1]);
  }
};

TEST_F(ReferenceDelayCommands, EvaluateFindsA10HzReferenceLate200MsWithin20MsAndShiftsIt) {
  const CommandResult r = evaluate(1);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const double d = said_delay(r.err);
  EXPECT_NEAR(d, 0.2, 0.02) << r.err;
  EXPECT_NE(r.err.find("the reference is shifted by it"), std::string::npos) << r.err;
  const json j = json::parse(r.out);
  EXPECT_NEAR(j.at("reference_delay_s").get<double>(), d, 0.0005);  // the line rounds to ms
  // Shifted, the estimator's velocity meets the reference better than unshifted: the shift reaches the scores.
  const CommandResult unshifted = evaluate(1, "--reference-delay 0");
  ASSERT_EQ(unshifted.exit_code, 0) << unshifted.err;
  EXPECT_NE(unshifted.err.find("reference delay: 0 s as declared (--reference-delay), the reference is not shifted"),
            std::string::npos)
      << unshifted.err;
  const json u = json::parse(unshifted.out);
  EXPECT_EQ(u.at("reference_delay_s").get<double>(), 0.0);
  EXPECT_LT(j["rmse_m_s"]["estimator"]["horizontal"].get<double>(),
            u["rmse_m_s"]["estimator"]["horizontal"].get<double>());
}

TEST_F(ReferenceDelayCommands, ADeclaredDelayIsAppliedAsGiven) {
  const CommandResult r = evaluate(1, "--reference-delay 0.15");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("reference delay: 0.15 s as declared"), std::string::npos) << r.err;
  EXPECT_DOUBLE_EQ(json::parse(r.out).at("reference_delay_s").get<double>(), 0.15);
}

TEST_F(ReferenceDelayCommands, AReferenceOnTimeIsFoundOnTime) {
  const CommandResult r = evaluate(2);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NEAR(said_delay(r.err), 0.0, 0.01) << r.err;
}

TEST_F(ReferenceDelayCommands, AHoverCannotTellSaysSoAndShiftsNothing) {
  const CommandResult r = evaluate(3);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("reference delay: cannot be estimated"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("the reference is not shifted"), std::string::npos) << r.err;
  EXPECT_EQ(json::parse(r.out).at("reference_delay_s").get<double>(), 0.0);
}

TEST_F(ReferenceDelayCommands, IdentifyRecordsTheDelayItFittedWithInParams) {
  const std::string out = (dir_ / "identified.json").string();
  const CommandResult r = run_imubridge("identify --db " + db_ + " --session 1 --out " + out);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const double d = said_delay(r.err);
  EXPECT_NEAR(d, 0.2, 0.02) << r.err;
  const estimator::ModelParams p = estimator::load_params(out);
  ASSERT_TRUE(p.identification.reference_delay);
  EXPECT_NEAR(*p.identification.reference_delay, d, 0.0005);
}

TEST_F(ReferenceDelayCommands, TheReferenceEffectsAreRefusedWhereNoReferenceIsWritten) {
  const CommandResult r =
      run_imubridge("sim --duration 1 --effect reference_delay=0.2 --file " + (dir_ / "bytes.bin").string());
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("apply to --db only"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace imubridge::test
