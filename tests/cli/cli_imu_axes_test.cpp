// One simulated flight written by `imubridge sim` in FRD, in FLU and in an arbitrary rotation, imported and
// identified as a user would: the identified physical parameters (lever arm, mounting, drag, in the body) and the
// velocity the estimator gives are the same whatever way up the IMU was; the only difference is the rotated samples'
// quantisation. A declaration the data contradict is said.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/support/run_command.hpp"

namespace imubridge::test {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

class ImuAxesCommand : public ::testing::Test {
 protected:
  static inline fs::path dir_;

  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / ("imubridge_axes_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    for (const auto& [name, axes] : kMounts) {
      const CommandResult r = run_imubridge("sim --scenario paper --seed 4 --duration 40 --imu-axes " + axes +
                                            " --db " + db(name));
      ASSERT_EQ(r.exit_code, 0) << r.err;
    }
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }

  static inline const std::vector<std::pair<std::string, std::string>> kMounts = {
      {"frd", "frd"}, {"flu", "flu"}, {"turned", "q:0.5,0.5,0.5,0.5"}};  // 120 deg about (1,1,1)
  static std::string db(const std::string& name) { return (dir_ / (name + ".db")).string(); }

  // identify --model full with the reference; the axes as recorded (auto unless the flight declared them).
  static json identify(const std::string& name, const std::string& extra = "") {
    const std::string out = (dir_ / (name + std::to_string(extra.size()) + ".json")).string();
    const CommandResult r = run_imubridge("identify --db " + db(name) + " --session 1 --model full --velocity "
                                          "reference --hold accel_bias --train 0:25 --validate 25: --out " + out +
                                          " " + extra);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    json j = json::parse(slurp(out));
    j["stderr"] = r.err;
    return j;
  }
};

TEST_F(ImuAxesCommand, EveryOrientationIdentifiesTheSameVehicle) {
  const json frd = identify("frd");
  for (const char* name : {"flu", "turned"}) {
    const json other = identify(name);
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(other["full"]["lever_arm"][i].get<double>(), frd["full"]["lever_arm"][i].get<double>(), 2e-3)
          << name << " lever arm " << i;
      EXPECT_NEAR(other["full"]["mounting"][i].get<double>(), frd["full"]["mounting"][i].get<double>(), 2e-3)
          << name << " mounting " << i;
    }
    for (int i = 0; i < 2; ++i) {
      EXPECT_NEAR(other["full"]["drag_quadratic"][i].get<double>(), frd["full"]["drag_quadratic"][i].get<double>(),
                  0.05 * frd["full"]["drag_quadratic"][i].get<double>() + 1e-3)
          << name << " drag " << i;
    }
  }
}

TEST_F(ImuAxesCommand, EveryOrientationGivesTheSameVelocity) {
  const auto velocity = [](const std::string& name) {
    const std::string params = (dir_ / (name + "-v.json")).string();
    EXPECT_EQ(run_imubridge("identify --db " + db(name) + " --session 1 --model full --velocity reference --hold "
                            "accel_bias --train 0:25 --validate 25: --out " + params).exit_code, 0);
    const CommandResult e = run_imubridge("evaluate --db " + db(name) + " --session 1 --params " + params);
    EXPECT_EQ(e.exit_code, 0) << e.err;
    return json::parse(e.out)["rmse_m_s"]["estimator"]["horizontal"].get<double>();
  };
  const double frd = velocity("frd");
  EXPECT_GT(frd, 0.0);
  EXPECT_NEAR(velocity("flu"), frd, 0.02 * frd);
  EXPECT_NEAR(velocity("turned"), frd, 0.02 * frd);
}

TEST_F(ImuAxesCommand, AutoFindsAZUpSensorAndAWrongDeclarationIsSaid) {
  const json automatic = identify("flu", "--imu-axes auto");
  EXPECT_NE(automatic["stderr"].get<std::string>().find("IMU axes flu (auto"), std::string::npos)
      << automatic["stderr"];
  const json wrong = identify("flu", "--imu-axes frd");
  const std::string err = wrong["stderr"];
  EXPECT_NE(err.find("warning: IMU axes declared frd"), std::string::npos) << err;
}

}  // namespace
}  // namespace imubridge::test
