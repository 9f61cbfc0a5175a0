// `imubridge sim` as a user runs it: the limits of its options, and its output for a given seed staying the same.
#include <gtest/gtest.h>

#include <cstdint>
#include <string>

#include "tests/support/run_command.hpp"
#include "tests/support/temp_dir.hpp"

namespace imubridge::test {
namespace {

// `sim OPTION VALUE` is refused for each value: exit code 2 and one line that says each of `said`.
void expect_refused(const std::string& option, std::initializer_list<const char*> values,
                    std::initializer_list<const char*> said) {
  TempDir dir;
  for (const char* value : values) {
    const auto r = run_imubridge("sim " + option + " " + value + " --file " + (dir / "f.bin").string());
    EXPECT_EQ(r.exit_code, 2) << option << " " << value;
    EXPECT_EQ(count_lines(r.err), 1) << r.err;
    for (const char* words : said) EXPECT_NE(r.err.find(words), std::string::npos) << r.err;
  }
}

TEST(SimCli, ADurationBeyondADayIsRefusedInOneLine) {
  expect_refused("--duration", {"1e300", "1e7", "86401", "0", "-1"}, {"at most 86400 s (24 h)"});
  EXPECT_NE(run_imubridge("sim --help").out.find("at most 86400 (24 h)"), std::string::npos);
}

TEST(SimCli, ASpeedOutsideItsRangeIsRefusedInOneLine) {
  expect_refused("--speed", {"1e-300", "0.0009", "1001", "1e300", "0", "-1"},
                 {"--speed ", "must be from 0.001 to 1000 times real time"});
  EXPECT_NE(run_imubridge("sim --help").out.find("from 0.001 to 1000"), std::string::npos);
}

TEST(SimCli, ARateOutsideItsRangeIsRefusedInOneLine) {
  expect_refused("--rate", {"1e9", "10001", "0.5", "0", "-100", "1e-300"}, {"must be from 1 to 10000 Hz"});
  TempDir dir;
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
