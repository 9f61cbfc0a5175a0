// --in-flight takes the flight from the log's own land detector when the session has one (the takeoff and landing
// events `import ulog` stores), says so, and percentages are of that flight at both ends.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <regex>
#include <string>

#include "estimator/params.hpp"
#include "store/store.hpp"
#include "tests/support/paper_params.hpp"
#include "tests/support/run_command.hpp"

namespace imubridge::test {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

class InFlight : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("imubridge_in_flight_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    db_ = (dir_ / "flights.db").string();
    params_ = (dir_ / "paper.json").string();
    estimator::save_params(params_, paper_params());
  }
  void TearDown() override { fs::remove_all(dir_); }

  fs::path dir_;
  std::string db_, params_;
};

// A simulated 60-s session (the sample times are the session's clock) whose land detector says 10-50 s.
TEST_F(InFlight, PercentagesAreOfTheLandDetectorsFlightAtBothEnds) {
  const CommandResult sim = run_imubridge("sim --scenario paper --seed 1 --duration 60 --db " + db_);
  ASSERT_EQ(sim.exit_code, 0) << sim.err;
  {
    store::Store store(db_);
    store.append_event(1, {.mono_ns = 10'000'000'000, .wall_ns = 0, .kind = "takeoff", .detail = "test"});
    store.append_event(1, {.mono_ns = 50'000'000'000, .wall_ns = 0, .kind = "landing", .detail = "test"});
  }
  const CommandResult e = run_imubridge("evaluate --db " + db_ + " --session 1 --params " + params_ +
                                        " --reference-delay 0 --in-flight --window 40%:");
  ASSERT_EQ(e.exit_code, 0) << e.err;
  EXPECT_NE(e.err.find("in flight 10.000:50.000 s (the log's land detector"), std::string::npos) << e.err;
  const json window = json::parse(e.out).at("window");
  EXPECT_NEAR(window[0].get<double>(), 26.0, 0.01);
  EXPECT_NEAR(window[1].get<double>(), 50.0, 0.01);  // the flight's end, not the session's (60 s)

  const std::string out = (dir_ / "identified.json").string();
  const CommandResult i = run_imubridge("identify --db " + db_ + " --session 1 --reference-delay 0 --in-flight "
                                        "--train 0:40% --out " + out);
  ASSERT_EQ(i.exit_code, 0) << i.err;
  const estimator::Identification id = estimator::load_params(out).identification;
  EXPECT_NEAR(id.fit_windows.at(0).start, 10.0, 0.01);
  EXPECT_NEAR(id.fit_windows.at(0).end, 26.0, 0.01);
  // Without --validate, validation runs from the end of training to the end of the flight.
  EXPECT_NEAR(id.validation_windows.at(0).end, 50.0, 0.01);
}

// A real PX4 flight whose land detector says 3.0-84.2 s from its first sample (../shared/data/ulog/SOURCE.md).
TEST_F(InFlight, ARealUlogFlightTakesItsLandDetectorsSpan) {
  const fs::path ulog = fs::path(IMUBRIDGE_SOURCE_DIR) / "../shared/data/ulog/x500v2_unregistered_msg_id.ulg";
  if (!fs::exists(ulog)) GTEST_SKIP() << "no " << ulog << " (../shared/data/ulog/SOURCE.md)";
  const CommandResult imported = run_imubridge("import ulog " + ulog.string() + " --db " + db_);
  ASSERT_EQ(imported.exit_code, 0) << imported.err;
  std::smatch airborne;
  ASSERT_TRUE(std::regex_search(imported.err, airborne, std::regex("from the first sample: ([0-9.]+)-([0-9.]+) s")))
      << imported.err;
  const CommandResult e = run_imubridge("evaluate --db " + db_ + " --session 1 --params " + params_ +
                                        " --in-flight --window 40%:");
  ASSERT_EQ(e.exit_code, 0) << e.err;
  std::smatch flight;
  ASSERT_TRUE(std::regex_search(e.err, flight, std::regex("in flight ([0-9.]+):([0-9.]+) s \\(the log's land detector")))
      << e.err;
  // The same flight as the import printed (the series starts at the first IMU sample; the log's other topics may
  // start a little earlier).
  EXPECT_NEAR(std::stod(flight[2]) - std::stod(flight[1]), std::stod(airborne[2]) - std::stod(airborne[1]), 0.5);
  const json window = json::parse(e.out).at("window");
  const double start = std::stod(flight[1]), end = std::stod(flight[2]);
  EXPECT_NEAR(window[0].get<double>(), start + 0.4 * (end - start), 0.05) << e.out;
  EXPECT_LE(window[1].get<double>(), end + 0.01) << e.out;
}

}  // namespace
}  // namespace imubridge::test
