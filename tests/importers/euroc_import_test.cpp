// EuRoC import: messy rows skipped and counted by line and reason, the frames' calibration and clock, the
// reference's conventions (NED, body -> NED), the velocity differentiator, and the real MH_01_easy flight.
#include "importers/euroc_import.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <numeric>
#include <sstream>

#include "importers/position_derivative.hpp"
#include "replay/text_table.hpp"
#include "tests/support/reported_problems.hpp"

namespace imubridge::importers {
namespace {

namespace fs = std::filesystem;
// The text tables the importer reads its files with (replay/text_table.hpp), tested here with the files they read.
using replay::format_ranges;
using replay::LinesByReason;
using replay::parse_scaled_integer;
using replay::read_table;
using replay::TableLayout;
using replay::TableRow;

const fs::path kFixture = fs::path(IMUBRIDGE_SOURCE_DIR) / "tests/data/euroc_junk";
constexpr std::int64_t kT0 = 1403636579758560000;  // the fixture's first IMU stamp, ns

class EurocImport : public ::testing::Test {
 protected:
  fs::path dir_ = fs::temp_directory_path() / ("imubridge_euroc_import_" + std::to_string(::getpid()));
  fs::path db_ = dir_ / "import.db";
  void SetUp() override { fs::create_directories(dir_); }
  void TearDown() override { fs::remove_all(dir_); }

  std::vector<protocol::Sample> samples(const store::Store& store, std::int64_t session) const {
    std::vector<protocol::Sample> out;
    store.for_each_sample(session, std::nullopt, [&](const protocol::Sample& s) { out.push_back(s); });
    return out;
  }
  std::vector<store::ReferenceRow> reference(const store::Store& store, std::int64_t session) const {
    std::vector<store::ReferenceRow> out;
    store.for_each_reference(session, [&](const store::ReferenceRow& r) { out.push_back(r); });
    return out;
  }
};

using Lines = std::vector<std::int64_t>;
using Places = std::map<std::string, std::string>;  // where the rows skipped for a reason are
using test::ReportedProblems;

TEST(ParseScaledInteger, IsExactWhereADoubleWouldRound) {
  // 1.40363657975856e18 is not a double: the nearest one is 256 ns away.
  EXPECT_EQ(parse_scaled_integer("1.40363657975856E+018", 0), 1403636579758560000);
  EXPECT_EQ(parse_scaled_integer("1403636580.83856", 9), 1403636580838560000);
  EXPECT_EQ(parse_scaled_integer("+3e+2", 0), 300);
  EXPECT_EQ(parse_scaled_integer("-12", 0), -12);
  EXPECT_EQ(parse_scaled_integer("0.000000001", 9), 1);
  EXPECT_EQ(parse_scaled_integer("007", 0), 7);
  EXPECT_EQ(parse_scaled_integer("0", 9), 0);
}

TEST(ParseScaledInteger, RoundsHalvesAwayFromZero) {
  EXPECT_EQ(parse_scaled_integer("1.4", 0), 1);
  EXPECT_EQ(parse_scaled_integer("0.5", 0), 1);
  EXPECT_EQ(parse_scaled_integer("-0.5", 0), -1);
  EXPECT_EQ(parse_scaled_integer("0.04", 0), 0);
  EXPECT_EQ(parse_scaled_integer("1403636763.8535", 3), 1403636763854);
}

TEST(ParseScaledInteger, RefusesWhatIsNotANumberOrDoesNotFit) {
  EXPECT_EQ(parse_scaled_integer("9223372036854775807", 0), std::numeric_limits<std::int64_t>::max());
  EXPECT_EQ(parse_scaled_integer("-9223372036854775808", 0), std::numeric_limits<std::int64_t>::min());
  EXPECT_EQ(parse_scaled_integer("9223372036854775808", 0), std::nullopt);
  EXPECT_EQ(parse_scaled_integer("1e19", 0), std::nullopt);
  EXPECT_EQ(parse_scaled_integer("1e9999999999", 0), std::nullopt);
  for (const char* bad : {"", "-", ".", "abc", "1.2.3", "1e", "1e+", "12 ", "0x10", "nan", "inf"}) {
    EXPECT_EQ(parse_scaled_integer(bad, 0), std::nullopt) << '"' << bad << '"';
  }
}

TEST(ReadTable, ReportsEverySkippedRowByReasonAndTakesTheRest) {
  std::istringstream in("# header\n1,2\r\n\n2,x\r\n3\n3,4\n3,5\n,\n4,5,6\n");
  LinesByReason skipped;
  std::vector<std::int64_t> taken;
  read_table(
      in, {',', 0, 2, 2},
      [&](const TableRow& row) -> std::optional<std::string> {
        taken.push_back(row.line);
        return std::nullopt;
      },
      skipped);
  EXPECT_EQ(taken, (Lines{2, 6}));
  EXPECT_EQ(skipped.count(), 5u);
  EXPECT_EQ(skipped.lines["not a finite number"], Lines{4});
  EXPECT_EQ(skipped.lines["1 field, expected 2"], Lines{5});
  EXPECT_EQ(skipped.lines["timestamp not after the previous row's"], Lines{7});
  EXPECT_EQ(skipped.lines["empty field"], Lines{8});
  EXPECT_EQ(skipped.lines["3 fields, expected 2"], Lines{9});
}

TEST(ReadTable, ARowTheHandlerRefusesIsSkippedAndDoesNotAdvanceTheClock) {
  std::istringstream in("5 1\n6 2\n6 3\n");
  LinesByReason skipped;
  std::vector<double> taken;
  read_table(
      in, {' ', 0, 2, 2},
      [&](const TableRow& row) -> std::optional<std::string> {
        if (row.values[0] == 1) return "refused";
        taken.push_back(row.values[0]);
        return std::nullopt;
      },
      skipped);
  EXPECT_EQ(taken, (std::vector<double>{2}));
  EXPECT_EQ(skipped.lines["refused"], Lines{1});
  EXPECT_EQ(skipped.lines["timestamp not after the previous row's"], Lines{3});
}

TEST(LinesByReason, SummarisesLinesAsRanges) {
  LinesByReason lines;
  for (std::int64_t line : {4, 5, 6, 9}) lines.add(line, "empty field");
  lines.add(12, "not a finite number");
  EXPECT_EQ(lines.summary(),
            (std::vector<std::string>{"4 rows: empty field (lines 4-6, 9)", "1 row: not a finite number (line 12)"}));
}

TEST(VelocityFromPositions, IsExactForAQuadraticOnUnevenTimesAlsoAtTheEnds) {
  std::vector<std::int64_t> t;
  std::vector<Eigen::Vector3d> p;
  const auto position = [](double s) { return Eigen::Vector3d(1 + 2 * s + 3 * s * s, -4 * s * s, 0.5); };
  for (std::int64_t k = 0; k < 100; ++k) {
    t.push_back(k * 5'000'000 + (k % 3) * 700'000);  // 5 ms with jitter
    p.push_back(position(static_cast<double>(t.back()) * 1e-9));
  }
  const auto v = velocity_from_positions(t, p);
  for (std::size_t i = 0; i < t.size(); ++i) {
    const double s = static_cast<double>(t[i]) * 1e-9;
    ASSERT_TRUE(v[i].has_value()) << i;
    EXPECT_NEAR(v[i]->x(), 2 + 6 * s, 1e-9) << i;
    EXPECT_NEAR(v[i]->y(), -8 * s, 1e-9) << i;
    EXPECT_NEAR(v[i]->z(), 0, 1e-9) << i;
  }
}

TEST(VelocityFromPositions, AveragesNoiseAwayOverItsWindow) {
  std::vector<std::int64_t> t;
  std::vector<Eigen::Vector3d> p;
  for (std::int64_t k = 0; k < 400; ++k) {  // 0.5 m/s along x with +-1 mm of noise: +, +, -, -, ...
    t.push_back(k * 5'000'000);
    p.emplace_back(0.5 * static_cast<double>(k) * 0.005 + (k % 4 < 2 ? 1e-3 : -1e-3), 0, 0);
  }
  const auto v = velocity_from_positions(t, p);
  // A central difference of neighbours would be off by 2 mm / 10 ms = 0.2 m/s at every sample.
  for (std::size_t i = 20; i < 380; ++i) EXPECT_NEAR(v[i]->x(), 0.5, 0.002) << i;
}

TEST(VelocityFromPositions, NoVelocityWithoutThreePositionsInTheWindow) {
  const std::vector<std::int64_t> t{0, 1'000'000'000, 1'005'000'000, 1'010'000'000};
  const std::vector<Eigen::Vector3d> p(4, Eigen::Vector3d::Zero());
  const auto v = velocity_from_positions(t, p);
  EXPECT_FALSE(v[0].has_value());  // alone in its +-0.1 s
  EXPECT_TRUE(v[1].has_value() && v[2].has_value() && v[3].has_value());
  EXPECT_THROW(velocity_from_positions(t, std::span(p).first(3)), std::invalid_argument);
}

TEST(VelocityFromPositions, TakesStampsFurtherApartThanAnInt64DifferenceHolds) {
  constexpr std::int64_t kFirst = std::numeric_limits<std::int64_t>::min();
  constexpr std::int64_t kLast = std::numeric_limits<std::int64_t>::max();
  const std::vector<std::int64_t> t{kFirst, 0, 5'000'000, 10'000'000, kLast};
  const std::vector<Eigen::Vector3d> p{{9, 9, 9}, {0, 0, 0}, {0.01, 0, 0}, {0.02, 0, 0}, {9, 9, 9}};
  const auto v = velocity_from_positions(t, p);
  EXPECT_FALSE(v[0].has_value());  // each end alone in its window
  EXPECT_FALSE(v[4].has_value());
  for (std::size_t i = 1; i <= 3; ++i) {
    ASSERT_TRUE(v[i].has_value()) << i;
    EXPECT_NEAR(v[i]->x(), 2, 1e-9) << i;
  }
}

TEST_F(EurocImport, SkipsEveryKindOfJunkRowAndCountsItByLine) {
  store::Store store(db_);
  ReportedProblems problems;
  const auto r = import_euroc(store, {.dir = kFixture, .on_problem = problems.callback()});
  EXPECT_EQ(r.imu.rows, 7u);
  EXPECT_EQ(problems.total(ProblemKind::skipped, "data.csv"), 9u);
  const Places want{{"3 fields, expected 7", "line 5"},
                    {"8 fields, expected 7", "line 13"},
                    {"empty field", "lines 14-15"},
                    {"not a finite number", "lines 8-9, 16-17"},
                    {"timestamp not after the previous row's", "line 11"}};
  EXPECT_EQ(problems.places(ProblemKind::skipped, "data.csv"), want);
  EXPECT_EQ(problems.places(ProblemKind::clipped), (Places{{"accel beyond +-65.534 m/s^2", "line 12"}}));
  EXPECT_EQ(problems.total(ProblemKind::clipped), 1u);
  EXPECT_FALSE(r.reference.has_value());  // the fixture has no state_groundtruth_estimate0

  // The same, for whoever reads the session later: one event per reason, with its count.
  std::map<std::string, std::int64_t> events;
  for (const auto& e : store.events(r.session)) events[e.kind] += e.count;
  EXPECT_EQ(events["import_skipped"], 9);
  EXPECT_EQ(events["import_clipped"], 1);
}

// A copy cut off in the middle of its last row: that row is a problem with its line, the rows before it are stored.
TEST_F(EurocImport, ATruncatedImuFileReportsItsCutRowAndKeepsTheRowsBeforeIt) {
  fs::create_directories(dir_ / "cut/mav0/imu0");
  std::ofstream(dir_ / "cut/mav0/imu0/data.csv") << "#timestamp [ns],w_x,w_y,w_z,a_x,a_y,a_z\n"
                                                    "1000000000,0,0,0,0,0,9.8\n"
                                                    "1005000000,0,0,0,0,0,9.8\n"
                                                    "1010000000,0,0,0,0,0,9.8\n"
                                                    "1015000000,0,0,0,0";
  store::Store store(db_);
  ReportedProblems problems;
  const auto r = import_euroc(store, {.dir = dir_ / "cut", .on_problem = problems.callback()});
  const auto skipped = problems.of(ProblemKind::skipped);
  ASSERT_EQ(skipped.size(), 1u);
  EXPECT_EQ(skipped[0].count, 1u);
  EXPECT_EQ(skipped[0].what, "row of " + (dir_ / "cut/mav0/imu0/data.csv").string());
  EXPECT_EQ(skipped[0].why, "5 fields, expected 7");
  EXPECT_EQ(skipped[0].where, "line 5");
  EXPECT_EQ(describe(skipped[0]),
            "1 row of " + (dir_ / "cut/mav0/imu0/data.csv").string() + " skipped: 5 fields, expected 7 (line 5)");
  EXPECT_EQ(r.imu.rows, 3u);
  EXPECT_EQ(samples(store, r.session).size(), 3u);
  std::vector<std::string> stored;  // the session's own words for it
  for (const auto& e : store.events(r.session)) {
    if (e.kind == "import_skipped") stored.push_back(e.detail);
  }
  EXPECT_EQ(stored, std::vector<std::string>{(dir_ / "cut/mav0/imu0/data.csv").string() +
                                             ": 1 row: 5 fields, expected 7 (line 5)"});
}

TEST_F(EurocImport, SamplesCarryTheRowsOnTheDatasetClockWithinHalfACount) {
  store::Store store(db_);
  const EurocImportOptions options{.dir = kFixture};
  const auto r = import_euroc(store, options);
  const auto got = samples(store, r.session);
  ASSERT_EQ(got.size(), 7u);
  // Rows 2, 3, 4, 7, 10, 12 and 18 of the file: stamps t0 + 0, 5, 10, 20, 25, 30 and 45 ms.
  const std::vector<std::int64_t> ms{0, 5, 10, 20, 25, 30, 45};
  const std::vector<std::array<double, 6>> rows{
      {0.01, -0.02, 0.03, 9.81, 0.1, -0.2},      {0.011, -0.021, 0.031, 9.8, 0.11, -0.21},
      {0.012, -0.022, 0.032, 9.79, 0.12, -0.22}, {0.014, -0.024, 0.034, 9.78, 0.13, -0.23},
      {0.015, -0.025, 0.035, 9.77, 0.14, -0.24}, {0.016, -0.026, 0.036, 65.534, 0.15, -0.25},  // 70 clipped
      {0.01, -0.026, 0.036, 9.75, 0.16, -0.26}};
  for (std::size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].seq, i);  // consecutive: skipped rows are not lost frames
    EXPECT_EQ(got[i].recv_mono_ns, kT0 + ms[i] * 1'000'000);
    EXPECT_EQ(got[i].device_time_us, ms[i] * 1000);  // the device clock starts with the first row
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR(got[i].gyro[a], rows[i][a], options.gyro_lsb / 2 + 1e-15) << i;
      EXPECT_NEAR(got[i].accel[a], rows[i][3 + a], options.accel_lsb / 2 + 1e-15) << i;
    }
  }
  const auto session = store.sessions().back();
  EXPECT_EQ(session.info.kind, "import");
  EXPECT_EQ(session.info.started_wall_ns, kT0);
  EXPECT_EQ(session.ended_wall_ns, kT0 + 45'000'000);
}

TEST_F(EurocImport, TheDeviceClockSpansStampsFurtherApartThanAnInt64DifferenceHolds) {
  fs::create_directories(dir_ / "mav0/imu0");
  std::ofstream(dir_ / "mav0/imu0/data.csv") << "-5,0,0,0,0,0,-9.81\n9223372036854775807,0,0,0,0,0,-9.81\n";
  store::Store store(db_);
  const auto r = import_euroc(store, {.dir = dir_});
  const auto got = samples(store, r.session);
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].device_time_us, 0);
  EXPECT_EQ(got[1].device_time_us, 9'223'372'036'854'776);  // 2^63 + 4 ns after the first row, to the nearest us
}

TEST_F(EurocImport, TumReferenceIsStoredInNedWithItsVelocityDerived) {
  store::Store store(db_);
  ReportedProblems problems;
  const auto r = import_euroc(
      store,
      {.dir = kFixture, .reference = ReferenceFile{kFixture / "reference_tum.txt"}, .on_problem = problems.callback()});
  ASSERT_TRUE(r.reference.has_value());
  EXPECT_TRUE(r.velocity_derived);
  EXPECT_EQ(r.reference->rows, 11u);
  const Places want{{"not a finite number", "line 13"},
                    {"4 fields, expected 8", "line 14"},
                    {"quaternion not of unit length", "line 15"}};
  EXPECT_EQ(problems.places(ProblemKind::skipped, "reference_tum.txt"), want);

  const auto rows = reference(store, r.session);
  ASSERT_EQ(rows.size(), 11u);
  // The file: z-up positions (1 + 2t + 3t^2, -1 + 0.5t, 2 - t^2) and the sensor turned 90 degrees about z.
  const Eigen::Matrix3d ned_from_zup = Eigen::Vector3d(1, -1, -1).asDiagonal();
  const Eigen::Matrix3d want_attitude =
      ned_from_zup * Eigen::AngleAxisd(std::numbers::pi / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  for (std::size_t k = 0; k < rows.size(); ++k) {
    const double t = 0.005 * static_cast<double>(k);
    EXPECT_EQ(rows[k].t_ns, kT0 + static_cast<std::int64_t>(k) * 5'000'000);  // the samples' clock
    const Eigen::Vector3d p = ned_from_zup * Eigen::Vector3d(1 + 2 * t + 3 * t * t, -1 + 0.5 * t, 2 - t * t);
    const Eigen::Vector3d v = ned_from_zup * Eigen::Vector3d(2 + 6 * t, 0.5, -2 * t);
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR(rows[k].position[a], p[a], 1e-12);
      ASSERT_TRUE(rows[k].velocity.has_value());
      EXPECT_NEAR((*rows[k].velocity)[a], v[a], 1e-8) << k;
    }
    const auto& q = rows[k].quat_wxyz;
    const Eigen::Matrix3d attitude = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).toRotationMatrix();
    EXPECT_TRUE(attitude.isApprox(want_attitude, 1e-12)) << attitude;
  }
}

TEST_F(EurocImport, MissingFilesAndFilesWithoutAUsableRowLeaveTheStoreUntouched) {
  store::Store store(db_);
  EXPECT_THROW(import_euroc(store, {.dir = dir_ / "nowhere"}), std::invalid_argument);
  const fs::path junk = dir_ / "junk";
  fs::create_directories(junk / "mav0/imu0");
  std::ofstream(junk / "mav0/imu0/data.csv") << "#timestamp,...\n,,,,,,\nStep: 0.005 = 1/200,,,,,,\n";
  try {
    import_euroc(store, {.dir = junk});
    ADD_FAILURE() << "imported a file without a single usable row";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("no usable rows"), std::string::npos) << e.what();
  }
  EXPECT_THROW(import_euroc(store, {.dir = kFixture, .reference = ReferenceFile{dir_ / "none.txt"}}),
               std::invalid_argument);
  EXPECT_TRUE(store.sessions().empty());
}

// The real flight (docs: /work/shared/data/real/euroc_mh01/SOURCE.md, whose measured numbers the checks use).
TEST_F(EurocImport, RealMh01EasyFlight) {
  const fs::path data = fs::path(IMUBRIDGE_SOURCE_DIR) / "../shared/data/real/euroc_mh01";
  if (!fs::exists(data / "mav0/imu0/data.csv")) GTEST_SKIP() << "no EuRoC MH_01_easy copy at " << data;
  store::Store store(db_);
  ReportedProblems problems;
  const auto r = import_euroc(
      store, {.dir = data, .reference = ReferenceFile{data / "MH_01_easy.txt"}, .on_problem = problems.callback()});
  EXPECT_EQ(r.imu.rows, 36820u);
  const Places junk{{"empty field", "lines 36822-36827"}, {"not a finite number", "line 36828"}};
  EXPECT_EQ(problems.places(ProblemKind::skipped, "data.csv"), junk);
  EXPECT_EQ(problems.total(ProblemKind::skipped, "data.csv"), 7u);
  EXPECT_TRUE(problems.of(ProblemKind::clipped).empty());  // the default resolutions cover its 60 m/s^2 and 4 rad/s
  ASSERT_TRUE(r.reference.has_value());
  EXPECT_EQ(r.reference->rows, 36382u);
  EXPECT_TRUE(problems.of(ProblemKind::skipped, "MH_01_easy.txt").empty());

  const auto imu = samples(store, r.session);
  const auto ref = reference(store, r.session);
  ASSERT_EQ(imu.size(), 36820u);
  EXPECT_EQ(imu.front().recv_mono_ns, 1403636579758560000);
  // The reference starts exactly 216 samples (1.08 s) after the IMU, on the same clock.
  EXPECT_EQ(ref.front().t_ns, imu[216].recv_mono_ns);

  // Conventions, checked against the source's own measurements: the IMU's specific force rotated by the reference
  // attitude into NED averages -9.745 m/s^2 on z (9.745 in EuRoC's z-up world) and about 0 horizontally; the
  // velocity differentiated from the positions has a mean horizontal speed of 0.39 m/s and a maximum of 1.96.
  Eigen::Vector3d f_sum = Eigen::Vector3d::Zero();
  double speed_sum = 0, speed_max = 0;
  std::size_t joined = 0, i = 0;
  for (const auto& row : ref) {
    while (i < imu.size() && imu[i].recv_mono_ns < row.t_ns) ++i;
    if (i == imu.size() || imu[i].recv_mono_ns != row.t_ns) continue;
    const Eigen::Quaterniond q(row.quat_wxyz[0], row.quat_wxyz[1], row.quat_wxyz[2], row.quat_wxyz[3]);
    f_sum += q * Eigen::Vector3d(imu[i].accel[0], imu[i].accel[1], imu[i].accel[2]);
    const double speed = std::hypot((*row.velocity)[0], (*row.velocity)[1]);
    speed_sum += speed;
    speed_max = std::max(speed_max, speed);
    ++joined;
  }
  ASSERT_GT(joined, 36000u);
  const Eigen::Vector3d f_mean = f_sum / static_cast<double>(joined);
  EXPECT_NEAR(f_mean.z(), -9.745, 0.01);
  EXPECT_NEAR(f_mean.x(), 0.010, 0.01);
  EXPECT_NEAR(f_mean.y(), -0.118, 0.01);  // +0.118 in the z-up world: y flips in NED
  EXPECT_NEAR(speed_sum / static_cast<double>(joined), 0.39, 0.01);
  EXPECT_NEAR(speed_max, 1.96, 0.05);
}

}  // namespace
}  // namespace imubridge::importers
