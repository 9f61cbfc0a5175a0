// `imubridge sim` as a user runs it: the limits of its options, and its output for a given seed staying the same.
#include <gtest/gtest.h>

#include <cstdint>
#include <string>

#include "tests/run_command.hpp"
#include "tests/temp_dir.hpp"

namespace imubridge::test {
namespace {

TEST(SimCli, ADurationBeyondADayIsRefusedInOneLine) {
  TempDir dir;
  for (const char* duration : {"1e300", "1e7", "86401", "0", "-1"}) {
    const auto r = run_imubridge(std::string("sim --duration ") + duration + " --file " + (dir / "f.bin").string());
    EXPECT_EQ(r.exit_code, 2) << duration;
    EXPECT_EQ(count_lines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find("at most 86400 s (24 h)"), std::string::npos) << r.err;
  }
  EXPECT_NE(run_imubridge("sim --help").out.find("at most 86400 (24 h)"), std::string::npos);
}

TEST(SimCli, ASpeedOutsideItsRangeIsRefusedInOneLine) {
  TempDir dir;
  for (const char* speed : {"1e-300", "0.0009", "1001", "1e300", "0", "-1"}) {
    const auto r = run_imubridge(std::string("sim --speed ") + speed + " --file " + (dir / "f.bin").string());
    EXPECT_EQ(r.exit_code, 2) << speed;
    EXPECT_EQ(count_lines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find("--speed "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("must be from 0.001 to 1000 times real time"), std::string::npos) << r.err;
  }
  EXPECT_NE(run_imubridge("sim --help").out.find("from 0.001 to 1000"), std::string::npos);
}

TEST(SimCli, ARateOutsideItsRangeIsRefusedInOneLine) {
  TempDir dir;
  for (const char* rate : {"1e9", "10001", "0.5", "0", "-100", "1e-300"}) {
    const auto r = run_imubridge(std::string("sim --rate ") + rate + " --file " + (dir / "f.bin").string());
    EXPECT_EQ(r.exit_code, 2) << rate;
    EXPECT_EQ(count_lines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find("must be from 1 to 10000 Hz"), std::string::npos) << r.err;
  }
  EXPECT_EQ(run_imubridge("sim --rate 10000 --duration 0.01 --file " + (dir / "f.bin").string()).exit_code, 0);
}

// The simulator streams its flight (its plan drawn as it goes); the bytes are those it wrote when it planned the
// whole flight first.
TEST(SimCli, TheSameSeedGivesTheSameBytesAsBefore) {
  TempDir dir;
  const auto r =
      run_imubridge("sim --scenario climb --seed 7 --duration 20 --protocol xbee --file " + (dir / "f.bin").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string bytes = slurp(dir / "f.bin");
  std::uint64_t hash = 14695981039346656037ull;
  for (const char c : bytes) hash = (hash ^ static_cast<std::uint8_t>(c)) * 1099511628211ull;
  EXPECT_EQ(bytes.size(), 197344u);
  EXPECT_EQ(hash, 0x058a23bd70874037ull);
}

}  // namespace
}  // namespace imubridge::test
