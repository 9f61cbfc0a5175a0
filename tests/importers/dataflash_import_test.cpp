// ArduPilot DataFlash: the reader on logs built here record by record (an older log timed in ms like ArduCopter 3.3's,
// a newer one timed in µs with FMTU, UNIT and MULT, IMU instances by name and by I field, ACC and GYR faster than
// IMU), damage (a truncated record, a corrupt header byte, a type no FMT defines), the import's samples, reference,
// events, parameters and holes, and the real ArduCopter flight log171.bin from ../shared/data/dataflash when present.
#include "importers/dataflash_import.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <variant>

#include "importers/dataflash.hpp"
#include "importers/log_import.hpp"
#include "tests/support/reported_problems.hpp"
#include "tests/support/stored_rows.hpp"
#include "tests/support/temp_dir.hpp"

namespace imubridge::importers {
namespace {

namespace fs = std::filesystem;
using test::ReportedProblems;
using test::session_config;
using test::stored_events;
using test::stored_reference;
using test::stored_samples;

const fs::path kShared = fs::path(IMUBRIDGE_SOURCE_DIR) / "../shared/data/dataflash";

// A DataFlash log, record by record. Numbers are given as stored: a `c` field's 1234 is 12.34.
class Writer {
 public:
  using Value = std::variant<double, std::string>;
  std::vector<std::uint8_t> bytes;
  std::vector<std::size_t> starts;  // each record's first byte

  Writer() { fmt(dataflash::kFmtType, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns"); }

  void fmt(std::uint8_t type, std::string_view name, std::string_view format, std::string_view columns) {
    std::size_t length = dataflash::kHeaderSize;
    for (const char c : format) length += dataflash::field_size(c);
    formats_[type] = std::string(format);
    header(dataflash::kFmtType);
    bytes.push_back(type);
    bytes.push_back(static_cast<std::uint8_t>(length));
    fixed(name, 4);
    fixed(format, 16);
    fixed(columns, 64);
  }
  void record(std::uint8_t type, const std::vector<Value>& values) {
    header(type);
    const std::string& format = formats_.at(type);
    for (std::size_t i = 0; i < format.size(); ++i) put(format[i], values.at(i));
  }

 private:
  std::map<std::uint8_t, std::string> formats_;

  void header(std::uint8_t type) {
    starts.push_back(bytes.size());
    bytes.insert(bytes.end(), {dataflash::kHead1, dataflash::kHead2, type});
  }
  void fixed(std::string_view text, std::size_t size) {
    std::string padded(text.substr(0, size));
    padded.resize(size, '\0');
    bytes.insert(bytes.end(), padded.begin(), padded.end());
  }
  template <typename T>
  void raw(T v) {
    const auto* p = reinterpret_cast<const std::uint8_t*>(&v);
    bytes.insert(bytes.end(), p, p + sizeof v);
  }
  void put(char type, const Value& value) {
    if (const auto* text = std::get_if<std::string>(&value)) return fixed(*text, dataflash::field_size(type));
    const double v = std::get<double>(value);
    switch (type) {
      case 'b':
        return raw(static_cast<std::int8_t>(v));
      case 'B':
      case 'M':
        return raw(static_cast<std::uint8_t>(v));
      case 'h':
      case 'c':
        return raw(static_cast<std::int16_t>(v));
      case 'H':
      case 'C':
        return raw(static_cast<std::uint16_t>(v));
      case 'i':
      case 'e':
      case 'L':
        return raw(static_cast<std::int32_t>(v));
      case 'I':
      case 'E':
        return raw(static_cast<std::uint32_t>(v));
      case 'f':
        return raw(static_cast<float>(v));
      case 'd':
        return raw(v);
      case 'q':
        return raw(static_cast<std::int64_t>(v));
      case 'Q':
        return raw(static_cast<std::uint64_t>(v));
      default:
        FAIL() << "no such field type " << type;
    }
  }
};

// ArduCopter 3.3's layout, timed in ms: IMU and IMU2 at 50 Hz for 2 s from 10 s with a hole of 1.02 s in the middle
// (the IMU's 50th sample at 10.98 s, the 51st at 12.0 s), EKF1 at 10 Hz flying north at 1 m/s with yaw 90 deg, a MODE
// change, EV armed (untimed: the time of the record before it), the land detector's takeoff and landing (EV 28, 18),
// MSG, PARM at the start and one change, and a GPS whose TimeMS (GPS time of week, not boot time) must not time the
// records after it.
constexpr std::uint32_t kOldT0Ms = 10'000;
constexpr std::size_t kOldSamples = 100;
std::uint32_t old_imu_ms(std::size_t i) {
  return i < 50 ? kOldT0Ms + 20 * static_cast<std::uint32_t>(i) : 12'000 + 20 * static_cast<std::uint32_t>(i - 50);
}

Writer old_log() {
  Writer w;
  w.fmt(129, "PARM", "Nf", "Name,Value");
  w.fmt(130, "GPS", "BIHBcLLeeEefI", "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs,VZ,T");
  w.fmt(131, "IMU", "IffffffIIf", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,ErrG,ErrA,Temp");
  w.fmt(132, "MSG", "Z", "Message");
  w.fmt(135, "IMU2", "IffffffIIf", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,ErrG,ErrA,Temp");
  w.fmt(140, "EKF1", "IccCffffffccc", "TimeMS,Roll,Pitch,Yaw,VN,VE,VD,PN,PE,PD,GX,GY,GZ");
  w.fmt(170, "MODE", "IMB", "TimeMS,Mode,ModeNum");
  w.fmt(13, "EV", "B", "Id");
  w.record(129, {std::string("ANGLE_MAX"), 4500.0});
  w.record(129, {std::string("INS_ACCOFFS_X"), 0.25});
  w.record(132, {std::string("APM:Copter V3.3-dev (ae3192b8)")});
  for (std::size_t i = 0; i < kOldSamples; ++i) {
    const double t = old_imu_ms(i);
    w.record(131, {t, 0.001 * static_cast<double>(i), 0.0, 0.0, 0.0, 0.0, -9.81, 0.0, 0.0, 40.0});
    w.record(135, {t, 0.5, 0.0, 0.0, 0.0, 0.0, -9.8, 0.0, 0.0, 41.0});
    if (i % 5 == 0) {
      const double k = static_cast<double>(i / 5);
      w.record(140, {t, 150.0, -250.0, 9000.0, 1.0, 0.0, -0.5, 0.1 * k, 0.0, -2.0, 0.0, 0.0, 0.0});
    }
    if (i == 10) {
      w.record(130, {3.0, 400'000'000.0, 1800.0, 9.0, 150.0, -353'000'000.0, 1'490'000'000.0, 100.0, 5000.0, 120.0,
                     9000.0, 0.0, t});
      w.record(170, {t, 5.0, 5.0});
      w.record(13, {10.0});  // armed, timed by the GPS record before it were its TimeMS boot time
    }
    if (i == 20) w.record(13, {28.0});  // the land detector: no longer landed (timed by this IMU2 record)
    if (i == 80) w.record(13, {18.0});  // and landed again
    if (i == 60) w.record(129, {std::string("ANGLE_MAX"), 3000.0});
  }
  return w;
}

// A newer layout, timed in µs, with UNIT, MULT and FMTU: IMU with an I field for instances 0 and 1 at 100 Hz, ACC and
// GYR of instance 0 at 400 Hz for 1 s from 20 s, XKF1 without angles for cores 0 and 1 (attitude from ATT), ARM, MSG
// and a message whose integer fields FMTU scales.
constexpr std::uint64_t kNewT0Us = 20'000'000;

Writer new_log() {
  Writer w;
  w.fmt(177, "UNIT", "QbZ", "TimeUS,Id,Label");
  w.fmt(178, "MULT", "Qbd", "TimeUS,Id,Mult");
  w.fmt(179, "FMTU", "QBNN", "TimeUS,FmtType,UnitIds,MultIds");
  w.fmt(10, "IMU", "QBffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ");
  w.fmt(11, "ACC", "QBQfff", "TimeUS,I,SampleUS,AccX,AccY,AccZ");
  w.fmt(12, "GYR", "QBQfff", "TimeUS,I,SampleUS,GyrX,GyrY,GyrZ");
  w.fmt(20, "XKF1", "QBffffff", "TimeUS,C,VN,VE,VD,PN,PE,PD");
  w.fmt(21, "ATT", "QccC", "TimeUS,Roll,Pitch,Yaw");
  w.fmt(22, "ARM", "QB", "TimeUS,ArmState");
  w.fmt(23, "MSG", "QZ", "TimeUS,Message");
  w.fmt(24, "BARO", "Qhcb", "TimeUS,Alt,Temp,Health");
  w.record(177, {0.0, static_cast<double>('s'), std::string("s")});
  w.record(177, {0.0, static_cast<double>('m'), std::string("m")});
  w.record(177, {0.0, static_cast<double>('O'), std::string("degC")});
  w.record(178, {0.0, static_cast<double>('F'), 1e-6});
  w.record(178, {0.0, static_cast<double>('B'), 1e-2});
  w.record(178, {0.0, static_cast<double>('C'), 1e-3});
  w.record(179, {0.0, 24.0, std::string("smO-"), std::string("FCB-")});
  w.record(23, {static_cast<double>(kNewT0Us), std::string("ArduCopter V4.5.7")});
  for (std::uint64_t i = 0; i < 400; ++i) {
    const double t = static_cast<double>(kNewT0Us + 2500 * i);
    w.record(11, {t, 0.0, t - 100, 0.0, 0.0, -9.81});
    w.record(12, {t, 0.0, t - 100, 0.002 * static_cast<double>(i), 0.0, 0.0});
    if (i % 4 == 0) {
      for (double instance : {0.0, 1.0}) w.record(10, {t, instance, instance, 0.0, 0.0, 0.0, 0.0, -9.7});
    }
    if (i % 40 == 0) {
      w.record(21, {t, 0.0, 0.0, 18000.0});  // yaw 180 deg
      for (double core : {1.0, 0.0}) w.record(20, {t + 1000, core, 2.0, 0.0, 0.0, core * 100, 0.0, -1.0});
      w.record(24, {t, 1234.0, 2550.0, 1.0});
    }
    if (i == 200) w.record(22, {t, 1.0});
  }
  w.record(21, {static_cast<double>(kNewT0Us + 1'000'000), 0.0, 0.0, 18000.0});
  return w;
}

class DataflashImport : public ::testing::Test {
 protected:
  test::TempDir dir_;
  fs::path write(const std::vector<std::uint8_t>& bytes, const std::string& name = "log.bin") {
    return dir_.write(name, bytes);
  }
};

// The holes every log importer records (importers/log_import.hpp): over the threshold only, between any two times a log
// may hold (euroc_fuzz found 2^63-1 after -5 overflowing the difference).
TEST(LogImportGaps, FindsTheHolesOverTheThresholdBetweenAnyTimes) {
  const std::vector<std::int64_t> t{0, 100'000'000, 1'200'000'000, 1'300'000'000};
  const Gaps gaps = find_gaps(t, 0.5, 0);
  ASSERT_EQ(gaps.holes.size(), 1u);
  EXPECT_EQ(gaps.holes[0].from_ns, 100'000'000);
  EXPECT_NEAR(gaps.holes[0].seconds(), 1.1, 1e-12);
  const std::vector<std::int64_t> extreme{-5, std::numeric_limits<std::int64_t>::max()};
  const Gaps far = find_gaps(extreme, 0.5, 0);
  ASSERT_EQ(far.holes.size(), 1u);
  EXPECT_NEAR(far.holes[0].seconds(), 9.223372036854775812e9, 1e3);
}

TEST(DataflashReader, ReadsAnOlderLogTimedInMilliseconds) {
  const Writer w = old_log();
  const dataflash::Log log = dataflash::parse(w.bytes);
  EXPECT_FALSE(log.damage);
  EXPECT_EQ(log.records, w.starts.size());
  const dataflash::Message* imu = log.message("IMU");
  ASSERT_NE(imu, nullptr);
  ASSERT_EQ(imu->size(), kOldSamples);
  EXPECT_EQ(imu->times[0], kOldT0Ms * 1000ull);
  EXPECT_EQ(imu->times[99], 12'980'000u);
  EXPECT_FLOAT_EQ(imu->value(7, *imu->field("GyrX")), 0.007f);
  const dataflash::Message* ekf = log.message("EKF1");
  ASSERT_EQ(ekf->size(), 20u);
  EXPECT_DOUBLE_EQ(ekf->value(0, *ekf->field("Roll")), 1.5);  // c: centi
  EXPECT_DOUBLE_EQ(ekf->value(0, *ekf->field("Yaw")), 90);    // C: centi, unsigned
  const dataflash::Message* gps = log.message("GPS");
  EXPECT_NEAR(gps->value(0, *gps->field("Lat")), -35.3, 1e-9);  // L: 1e-7 degrees
  EXPECT_EQ(gps->integer(0, *gps->field("TimeMS")), 400'000'000);
  // Untimed records take the time of the last timed record before them, never a GPS's time of week.
  const dataflash::Message* parm = log.message("PARM");
  ASSERT_EQ(parm->size(), 3u);
  EXPECT_EQ(parm->times[0], 0u);
  EXPECT_EQ(parm->text(0, *parm->field("Name")), "ANGLE_MAX");
  EXPECT_TRUE(std::isnan(parm->value(0, *parm->field("Name"))));
  EXPECT_EQ(parm->times[2], old_imu_ms(60) * 1000ull);
  EXPECT_EQ(log.message("EV")->times[0], old_imu_ms(10) * 1000ull);
  EXPECT_EQ(log.message("MSG")->text(0, 0), "APM:Copter V3.3-dev (ae3192b8)");
  EXPECT_EQ(log.message("NKF1"), nullptr);
}

TEST(DataflashReader, ScalesByFmtuUnitAndMult) {
  const dataflash::Log log = dataflash::parse(new_log().bytes);
  EXPECT_FALSE(log.damage);
  EXPECT_EQ(log.units.at('O'), "degC");
  EXPECT_EQ(log.multipliers.at('C'), 1e-3);
  const dataflash::Message* baro = log.message("BARO");
  ASSERT_NE(baro, nullptr);
  EXPECT_EQ(baro->fields[1].unit, "m");
  EXPECT_DOUBLE_EQ(baro->value(0, 1), 1.234);                           // h with MULT C: 1e-3
  EXPECT_DOUBLE_EQ(baro->value(0, 2), 25.5);                            // c with MULT B: the same 0.01, applied once
  EXPECT_EQ(baro->value(0, 3), 1);                                      // '-': as stored
  EXPECT_EQ(baro->integer(0, 0), static_cast<std::int64_t>(kNewT0Us));  // TimeUS: µs, whatever its multiplier
  EXPECT_EQ(baro->times[0], kNewT0Us);
  EXPECT_EQ(log.message("IMU")->size(), 200u);
}

TEST(DataflashReader, RefusesWhatIsNoDataflashLogInOneLine) {
  const auto error = [](const std::vector<std::uint8_t>& bytes) -> std::string {
    try {
      dataflash::parse(bytes);
    } catch (const dataflash::ParseError& e) {
      return e.what();
    }
    return "";
  };
  const std::string not_df = "not an ArduPilot DataFlash log: it does not begin with a FMT record (0xA3 0x95 0x80)";
  EXPECT_EQ(error({}), not_df);
  EXPECT_EQ(error(std::vector<std::uint8_t>(200, 'x')), not_df);
  Writer broken;
  broken.bytes[4] = 90;  // FMT's length, not the 89 bytes FMT takes
  EXPECT_EQ(error(broken.bytes),
            "not a readable DataFlash log: its first record is a FMT for type 128 (FMT) redefining FMT otherwise");
  EXPECT_EQ(error(Writer().bytes), "");  // a log of one FMT is a log, of nothing
}

// A damaged log's names are whatever bytes it holds: the damage still reads as one line (dataflash_fuzz found a
// name with a newline in it).
TEST(DataflashReader, DamageShowsTheLogsNamesOnOneLine) {
  Writer w;
  w.fmt(24, std::string_view("BA\n\x10", 4), "BBB", "");  // three field types, no field names
  const dataflash::Log log = dataflash::parse(w.bytes);
  ASSERT_TRUE(log.damage.has_value());
  EXPECT_EQ(log.damage->find('\n'), std::string::npos) << *log.damage;
  EXPECT_NE(log.damage->find("(BA\\x0a\\x10)"), std::string::npos) << *log.damage;
}

// Damage ends reading where it is, in one line that says what and where; the records before it are all there.
TEST(DataflashReader, ReadsUpToTheDamage) {
  const Writer w = old_log();
  const std::size_t middle = w.starts[std::size(w.starts) / 2];
  const auto imu_before = [&](const dataflash::Log& log) { return log.message("IMU")->size(); };
  const dataflash::Log full = dataflash::parse(w.bytes);

  std::vector<std::uint8_t> truncated(w.bytes.begin(), w.bytes.end() - 5);
  const dataflash::Log cut = dataflash::parse(truncated);
  ASSERT_TRUE(cut.damage);
  EXPECT_EQ(*cut.damage, "at byte " + std::to_string(w.starts.back()) + ": a IMU2 record cut short (" +
                             std::to_string(truncated.size() - w.starts.back()) + " bytes of its 43; the file ends)");
  EXPECT_EQ(imu_before(cut), kOldSamples);
  EXPECT_EQ(cut.message("IMU2")->size(), kOldSamples - 1);

  std::vector<std::uint8_t> corrupt = w.bytes;
  corrupt[middle + 1] = 0x00;
  const dataflash::Log header = dataflash::parse(corrupt);
  ASSERT_TRUE(header.damage);
  EXPECT_EQ(*header.damage, "at byte " + std::to_string(middle) + ": no record header (0xA3 0x95) but 0xa3 0x00");
  EXPECT_GT(imu_before(header), 10u);
  EXPECT_LT(imu_before(header), kOldSamples);

  std::vector<std::uint8_t> unknown = w.bytes;
  unknown[middle + 2] = 0x42;
  const dataflash::Log type = dataflash::parse(unknown);
  ASSERT_TRUE(type.damage);
  EXPECT_EQ(*type.damage,
            "at byte " + std::to_string(middle) + ": a record of type 66, which no FMT before it defines");
  EXPECT_EQ(imu_before(type), imu_before(header));

  Writer redefined = old_log();
  redefined.fmt(131, "IMU", "Ifff", "TimeMS,GyrX,GyrY,GyrZ");
  const dataflash::Log fmt = dataflash::parse(redefined.bytes);
  ASSERT_TRUE(fmt.damage);
  EXPECT_EQ(*fmt.damage, "at byte " + std::to_string(w.bytes.size()) + ": a FMT redefining type 131 (IMU) otherwise");
  EXPECT_EQ(imu_before(fmt), imu_before(full));

  // Cut anywhere after the first FMT, the log reads up to the cut, in one line.
  for (std::size_t size = dataflash::kFmtLength; size < w.bytes.size(); size += 97) {
    const dataflash::Log log = dataflash::parse(std::span(w.bytes.data(), size));
    ASSERT_EQ(log.damage.has_value(), std::find(w.starts.begin(), w.starts.end(), size) == w.starts.end()) << size;
    if (log.damage) {
      EXPECT_EQ(log.damage->find('\n'), std::string::npos);
    }
  }
}

TEST_F(DataflashImport, SamplesReferenceEventsParametersAndHolesOfAnOlderLog) {
  store::Store store(dir_ / "import.db");
  ReportedProblems problems;
  const auto r = import_dataflash(store, {.file = write(old_log().bytes), .on_problem = problems.callback()});
  EXPECT_EQ(r.instance, 0u);
  EXPECT_EQ(r.imu_source, "IMU");
  EXPECT_EQ(r.imus.at(0), "IMU: 100");
  EXPECT_EQ(r.imus.at(1), "IMU2: 100");
  EXPECT_EQ(r.samples, kOldSamples);
  EXPECT_TRUE(problems.all.empty());
  EXPECT_EQ(r.first_us, kOldT0Ms * 1000ull);
  EXPECT_EQ(r.last_us, 12'980'000u);
  EXPECT_FALSE(r.axes.mismatch);

  const auto s = stored_samples(store, r.session);
  ASSERT_EQ(s.size(), kOldSamples);
  EXPECT_EQ(s[0].device_time_us, 10'000'000);
  EXPECT_EQ(s[0].recv_mono_ns, 10'000'000'000);
  EXPECT_NEAR(s[0].accel[2], -9.81, 2.5e-3);
  EXPECT_NEAR(s[70].gyro[0], 0.07, 0.55e-3);
  EXPECT_EQ(s[99].seq, 99u);

  // EKF1: position and velocity NED, attitude from its own angles (roll 1.5, pitch -2.5, yaw 90 deg).
  const auto ref = stored_reference(store, r.session);
  EXPECT_EQ(r.reference_source, "EKF1 (attitude from its Roll, Pitch, Yaw)");
  ASSERT_EQ(ref.size(), 20u);
  EXPECT_EQ(ref[3].t_ns, static_cast<std::int64_t>(old_imu_ms(15)) * 1'000'000);
  EXPECT_NEAR(ref[3].position[0], 0.3, 1e-6);
  EXPECT_EQ(ref[3].position[2], -2);
  ASSERT_TRUE(ref[3].velocity);
  EXPECT_EQ((*ref[3].velocity)[0], 1);
  const Eigen::Quaterniond q(ref[3].quat_wxyz[0], ref[3].quat_wxyz[1], ref[3].quat_wxyz[2], ref[3].quat_wxyz[3]);
  const Eigen::Vector3d ypr = q.toRotationMatrix().eulerAngles(2, 1, 0);
  EXPECT_NEAR(ypr[0], M_PI / 2, 1e-9);
  EXPECT_NEAR(ypr[1], -0.025 * M_PI / 180 * 100, 1e-9);
  EXPECT_NEAR(ypr[2], 0.015 * M_PI / 180 * 100, 1e-9);

  const auto log = stored_events(store, r.session, "log");
  ASSERT_EQ(log.size(), 1u);
  EXPECT_EQ(log[0].detail, "APM:Copter V3.3-dev (ae3192b8)");
  const auto mode = stored_events(store, r.session, "mode");
  ASSERT_EQ(mode.size(), 1u);
  EXPECT_EQ(mode[0].detail, "mode 5 (LOITER)");
  EXPECT_EQ(mode[0].mono_ns, static_cast<std::int64_t>(old_imu_ms(10)) * 1'000'000);
  const auto arming = stored_events(store, r.session, "arming");
  ASSERT_EQ(arming.size(), 1u);
  EXPECT_EQ(arming[0].detail, "armed (EV 10)");
  EXPECT_EQ(arming[0].mono_ns, mode[0].mono_ns);
  EXPECT_EQ(r.log_events, 1u);
  EXPECT_EQ(r.mode_changes, 1u);
  EXPECT_EQ(r.arming_changes, 1u);
  const auto takeoff = stored_events(store, r.session, "takeoff");
  const auto landing = stored_events(store, r.session, "landing");
  ASSERT_EQ(takeoff.size(), 1u);
  ASSERT_EQ(landing.size(), 1u);
  EXPECT_EQ(takeoff[0].detail, "the land detector: no longer landed (EV 28, NOT_LANDED)");
  EXPECT_EQ(takeoff[0].mono_ns, static_cast<std::int64_t>(old_imu_ms(20)) * 1'000'000);
  EXPECT_EQ(landing[0].detail, "the land detector: landed (EV 18, LAND_COMPLETE)");
  EXPECT_EQ(landing[0].mono_ns, static_cast<std::int64_t>(old_imu_ms(80)) * 1'000'000);
  EXPECT_EQ(r.land_detector_changes, 2u);

  // The hole: from the 50th sample at 10.98 s to the 51st at 12.0 s, 1.02 s over the default 0.5 s.
  ASSERT_EQ(r.gaps.holes.size(), 1u);
  EXPECT_EQ(r.gaps.holes[0].from_ns, 10'980'000'000);
  EXPECT_EQ(r.gaps.holes[0].to_ns, 12'000'000'000);
  const auto gap = stored_events(store, r.session, "gap");
  ASSERT_EQ(gap.size(), 1u);
  EXPECT_EQ(gap[0].mono_ns, 10'980'000'000);
  EXPECT_EQ(gap[0].detail, "no IMU sample for 1.020 s, from 0.980 s to 2.000 s of the session (over 0.5 s)");

  const auto c = session_config(store, r.session).at("import");
  EXPECT_EQ(c.at("format"), "dataflash");
  EXPECT_EQ(r.params, 2u);
  EXPECT_EQ(c.at("params").at("ANGLE_MAX"), 4500);
  EXPECT_EQ(c.at("params").at("INS_ACCOFFS_X"), 0.25);
  ASSERT_EQ(c.at("param_changes").size(), 1u);
  EXPECT_EQ(c.at("param_changes")[0].at("value"), 3000);
  EXPECT_EQ(c.at("messages").at("IMU2"), kOldSamples);
  EXPECT_EQ(c.at("imu_instance"), 0);
}

TEST_F(DataflashImport, AnotherInstanceAGapThresholdAndNoReferenceWhenAsked) {
  store::Store store(dir_ / "import.db");
  const fs::path file = write(old_log().bytes);
  const auto r = import_dataflash(store, {.file = file, .reference = false, .imu = 1, .gap_threshold_s = 2});
  EXPECT_EQ(r.imu_source, "IMU2");
  EXPECT_EQ(r.samples, kOldSamples);
  EXPECT_NEAR(stored_samples(store, r.session)[0].gyro[0], 0.5, 0.55e-3);
  EXPECT_TRUE(r.gaps.holes.empty());  // 1.02 s is no hole over 2 s
  EXPECT_TRUE(stored_events(store, r.session, "gap").empty());
  EXPECT_EQ(r.reference_rows, 0u);
  EXPECT_TRUE(stored_reference(store, r.session).empty());

  const auto refused = [&](DataflashImportOptions options) -> std::string {
    try {
      import_dataflash(store, options);
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_EQ(refused({.file = file, .imu = 2}),
            file.string() + ": no IMU instance 2 (its IMUs: 0: IMU: 100; 1: IMU2: 100)");
  EXPECT_EQ(refused({.file = file, .gap_threshold_s = 0}), "--gap-threshold must be a positive number of seconds");
  Writer no_imu;
  no_imu.fmt(132, "MSG", "Z", "Message");
  no_imu.record(132, {std::string("hello")});
  EXPECT_EQ(refused({.file = write(no_imu.bytes, "no_imu.bin")}),
            (dir_ / std::string("no_imu.bin")).string() + ": no IMU samples (no IMU, or ACC and GYR, records)");
  EXPECT_EQ(store.sessions().size(), 1u);  // nothing written by the refusals
}

TEST_F(DataflashImport, AccAndGyrWhereFasterInstancesByIFieldAndTheEkfWithAtt) {
  store::Store store(dir_ / "import.db");
  const fs::path file = write(new_log().bytes);
  const auto r = import_dataflash(store, {.file = file});
  EXPECT_EQ(r.imus.at(0), "IMU[0]: 100, ACC[0]+GYR[0]: 400");
  EXPECT_EQ(r.imus.at(1), "IMU[1]: 100");
  EXPECT_EQ(r.imu_source, "ACC[0]+GYR[0]");
  // Each gyro sample with the accelerometer at its time (here the same), at the sensor's time (SampleUS).
  EXPECT_EQ(r.samples, 400u);
  EXPECT_EQ(r.first_us, kNewT0Us - 100);
  const auto s = stored_samples(store, r.session);
  ASSERT_EQ(s.size(), 400u);
  EXPECT_NEAR(s[10].gyro[0], 0.02, 0.55e-3);
  EXPECT_NEAR(s[10].accel[2], -9.81, 2.5e-3);
  EXPECT_TRUE(r.gaps.holes.empty());

  // XKF1's core 0 only, attitude (yaw 180 deg) from ATT, at the EKF's times.
  EXPECT_EQ(r.reference_source, "XKF1 (attitude from ATT)");
  const auto ref = stored_reference(store, r.session);
  ASSERT_EQ(ref.size(), 10u);
  for (const auto& row : ref) EXPECT_EQ(row.position[0], 0);
  EXPECT_EQ(ref[0].t_ns, static_cast<std::int64_t>(kNewT0Us + 1000) * 1000);
  EXPECT_NEAR(std::abs(ref[0].quat_wxyz[3]), 1, 1e-9);
  EXPECT_EQ((*ref[0].velocity)[0], 2);

  const auto arming = stored_events(store, r.session, "arming");
  ASSERT_EQ(arming.size(), 1u);
  EXPECT_EQ(arming[0].detail, "armed (ARM)");
  EXPECT_EQ(stored_events(store, r.session, "log").at(0).detail, "ArduCopter V4.5.7");

  const auto imu1 = import_dataflash(store, {.file = file, .imu = 1});
  EXPECT_EQ(imu1.imu_source, "IMU[1]");
  EXPECT_EQ(imu1.samples, 100u);
  EXPECT_NEAR(stored_samples(store, imu1.session)[0].gyro[0], 1, 0.55e-3);
}

TEST_F(DataflashImport, ImportsADamagedLogUpToTheDamageAndSaysSo) {
  const Writer w = old_log();
  std::vector<std::uint8_t> bytes = w.bytes;
  const std::size_t at = w.starts[w.starts.size() / 2];
  bytes[at] = 0x00;
  store::Store store(dir_ / "import.db");
  const fs::path file = write(bytes);
  ReportedProblems problems;
  const auto r = import_dataflash(store, {.file = file, .on_problem = problems.callback()});
  const std::string damage = "at byte " + std::to_string(at) + ": no record header (0xA3 0x95) but 0x00 0x95";
  EXPECT_EQ(problems.all,
            (std::vector<importers::ImportProblem>{{.kind = ProblemKind::damaged,
                                                    .count = 1,
                                                    .what = "stretch of " + file.string(),
                                                    .why = damage + "; everything before it is imported"}}));
  EXPECT_GT(r.samples, 10u);
  EXPECT_LT(r.samples, kOldSamples);
  EXPECT_EQ(stored_samples(store, r.session).size(), r.samples);
  const auto damaged = stored_events(store, r.session, "import_damaged");
  ASSERT_EQ(damaged.size(), 1u);
  EXPECT_EQ(damaged[0].detail,
            file.string() + ": read up to the damage, " + damage + "; everything before it is imported");
}

// ../shared/data/dataflash/log171.bin: an ArduCopter 3.3 flight of about 243 s in LOITER (SOURCE.md there).
TEST_F(DataflashImport, TheArduCopterFlightLog171) {
  const fs::path path = kShared / "log171.bin";
  if (!fs::exists(path)) GTEST_SKIP() << "no " << path << " (the real ArduCopter log is in ../shared only)";
  store::Store store(dir_ / "log171.db");
  ReportedProblems problems;
  const auto r = import_dataflash(store, {.file = path, .on_problem = problems.callback()});
  EXPECT_TRUE(problems.all.empty());
  EXPECT_EQ(r.imu_source, "IMU");
  EXPECT_EQ(r.imus.at(0), "IMU: 11916");
  EXPECT_EQ(r.imus.at(1), "IMU2: 11916");
  EXPECT_EQ(r.imus.at(2), "IMU3: 11916");
  EXPECT_EQ(r.samples, 11916u);
  const double span_s = static_cast<double>(r.last_us - r.first_us) * 1e-6;
  EXPECT_GT(span_s, 230);
  EXPECT_LT(span_s, 250);
  EXPECT_NEAR(static_cast<double>(r.samples - 1) / span_s, 50, 1);  // the flight's IMU rate
  EXPECT_FALSE(r.axes.mismatch);                                    // FRD: gravity on -z at rest
  const auto s = stored_samples(store, r.session);
  ASSERT_EQ(s.size(), 11916u);
  // The first sample at rest (AccZ -9.5875 m/s^2 in the file), and gravity's size on average over the flight (which
  // ends upside down: ACRO, then ERR records).
  EXPECT_NEAR(s.front().accel[2], -9.5875, 2.5e-3);
  double mean_norm = 0;
  for (const auto& sample : s) mean_norm += std::hypot(sample.accel[0], sample.accel[1], sample.accel[2]) / 11916.0;
  EXPECT_NEAR(mean_norm, 9.81, 0.3);

  EXPECT_EQ(r.reference_source, "EKF1 (attitude from its Roll, Pitch, Yaw)");
  EXPECT_EQ(r.reference_rows, 2383u);
  const auto ref = stored_reference(store, r.session);
  ASSERT_EQ(ref.size(), 2383u);
  double top_speed = 0;
  for (const auto& row : ref) {
    ASSERT_TRUE(row.velocity);
    top_speed = std::max(top_speed, std::hypot((*row.velocity)[0], (*row.velocity)[1]));
  }
  EXPECT_GT(top_speed, 5);  // GPS says up to 12.2 m/s
  EXPECT_LT(top_speed, 15);

  EXPECT_EQ(r.log_events, 4u);
  EXPECT_EQ(stored_events(store, r.session, "log").at(0).detail, "APM:Copter V3.3-dev (ae3192b8)");
  const auto modes = stored_events(store, r.session, "mode");
  ASSERT_EQ(modes.size(), 3u);
  EXPECT_EQ(modes[0].detail, "mode 5 (LOITER)");
  EXPECT_EQ(modes[2].detail, "mode 1 (ACRO)");
  ASSERT_EQ(stored_events(store, r.session, "arming").size(), 1u);
  EXPECT_EQ(stored_events(store, r.session, "arming")[0].detail, "armed (EV 10)");
  EXPECT_GT(r.params, 400u);
  EXPECT_EQ(session_config(store, r.session).at("import").at("messages").at("EKF1"), 2383);
}

}  // namespace
}  // namespace imubridge::importers
