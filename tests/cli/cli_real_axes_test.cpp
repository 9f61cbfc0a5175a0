// One real flight in the axes its IMU recorded it in (the ANSFL DOT's, z up) and rewritten in FRD (y and z turned
// over, as a z-down autopilot would log it) takes the same diagnose steps and gives the same model: the search
// depends on the vehicle, not on the IMU's orientation (issue 24). Skips without ../shared/data/real/ansfl_vertical.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "tests/support/run_command.hpp"

namespace imubridge::test {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

const fs::path kFlight = fs::path(IMUBRIDGE_SOURCE_DIR) / "../shared/data/real/ansfl_vertical/path_30";

// The flight's EuRoC folder again under `to`, its IMU turned from FLU to FRD: (x, y, z) -> (x, -y, -z), gyro and
// accelerometer alike. The reference (the vehicle's pose in the world) stays as it is.
void write_frd_copy(const fs::path& to) {
  fs::create_directories(to / "mav0/imu0");
  fs::copy(kFlight / "mav0/state_groundtruth_estimate0", to / "mav0/state_groundtruth_estimate0",
           fs::copy_options::recursive);
  std::ifstream in(kFlight / "mav0/imu0/data.csv");
  std::ofstream out(to / "mav0/imu0/data.csv");
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') {
      out << line << '\n';
      continue;
    }
    std::vector<std::string> cells;
    std::stringstream row(line);
    for (std::string cell; std::getline(row, cell, ',');) cells.push_back(cell);
    ASSERT_EQ(cells.size(), 7u) << line;
    const auto negate = [](const std::string& v) { return v[0] == '-' ? v.substr(1) : "-" + v; };
    out << cells[0] << ',' << cells[1] << ',' << negate(cells[2]) << ',' << negate(cells[3]) << ',' << cells[4] << ','
        << negate(cells[5]) << ',' << negate(cells[6]) << '\n';
  }
}

TEST(RealFlightAxes, FluAndFrdTakeTheSameDiagnoseSteps) {
  if (!fs::exists(kFlight)) GTEST_SKIP() << "no " << kFlight << " (../shared/data/real/ansfl_vertical/SOURCE.md)";
  const fs::path dir = fs::temp_directory_path() / ("imubridge_real_axes_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  write_frd_copy(dir / "frd");
  const std::string db = (dir / "flights.db").string();
  for (const fs::path& flight : {kFlight, dir / "frd"}) {
    const CommandResult r = run_imubridge("import euroc " + flight.string() + " --db " + db);
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  std::vector<json> reports;
  for (const char* session : {"1", "2"}) {
    const fs::path report = dir / (std::string("report-") + session);
    const CommandResult r = run_imubridge(
        "diagnose --db " + db + " --session " + session +
        " --model full --velocity reference --train 0:70% --validate 70%: --max-steps 2 --report " + report.string());
    ASSERT_EQ(r.exit_code, 0) << r.err;
    reports.push_back(json::parse(slurp(report / "report.json")));
  }
  EXPECT_NE(reports[0]["imu_axes"].get<std::string>().find("flu"), std::string::npos) << reports[0]["imu_axes"];
  EXPECT_NE(reports[1]["imu_axes"].get<std::string>().find("frd"), std::string::npos) << reports[1]["imu_axes"];
  const auto steps = [](const json& report) {
    std::vector<std::string> names;
    for (const json& s : report["steps"]) names.push_back(s["effect"]);
    return names;
  };
  EXPECT_EQ(steps(reports[0]), steps(reports[1]));
  // The same vehicle in both: the base's residual and the final velocity agree to within the fits' tolerance.
  const double base0 = reports[0]["base"]["rmse_validation"], base1 = reports[1]["base"]["rmse_validation"];
  EXPECT_NEAR(base0, base1, 0.01 * base0);
  const auto final_velocity = [](const json& report) {
    const json& last = report["steps"].empty() ? report["base"] : report["steps"].back();
    return last["velocity_rmse_m_s"]["validation"]["horizontal"].get<double>();
  };
  EXPECT_NEAR(final_velocity(reports[0]), final_velocity(reports[1]), 0.05 * final_velocity(reports[0]));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace imubridge::test
