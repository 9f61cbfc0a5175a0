// PX4 ULog: the reader on a file built here message by message (nested formats, padding, every message type,
// appended data, truncation and corrupt definitions), the import's samples, reference and events, and the PX4
// sample logs of pyulog (tests/data/ulog, and sample.ulg from ../shared/data/ulog when present).
#include "importers/ulog_import.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "importers/ulog.hpp"
#include "tests/support/reported_problems.hpp"
#include "tests/support/stored_rows.hpp"

namespace imubridge::importers {
namespace {

namespace fs = std::filesystem;
using test::ReportedProblems;
using test::session_config;
using test::stored_events;
using test::stored_reference;
using test::stored_samples;

const fs::path kData = fs::path(IMUBRIDGE_SOURCE_DIR) / "tests/data/ulog";
const fs::path kShared = fs::path(IMUBRIDGE_SOURCE_DIR) / "../shared/data/ulog";

// A ULog file, message by message.
class Writer {
 public:
  std::vector<std::uint8_t> bytes;

  explicit Writer(std::uint8_t incompat0 = 0) {
    bytes = {0x55, 0x4c, 0x6f, 0x67, 0x01, 0x12, 0x35, 0x01};
    put<std::uint64_t>(bytes, 1000);
    std::vector<std::uint8_t> flags(40, 0);
    flags[8] = incompat0;
    message('B', flags);
  }
  template <typename T>
  static void put(std::vector<std::uint8_t>& out, T value) {
    const auto* p = reinterpret_cast<const std::uint8_t*>(&value);
    out.insert(out.end(), p, p + sizeof value);
  }
  static void put(std::vector<std::uint8_t>& out, std::string_view text) {
    out.insert(out.end(), text.begin(), text.end());
  }
  void message(char type, const std::vector<std::uint8_t>& body) {
    put<std::uint16_t>(bytes, static_cast<std::uint16_t>(body.size()));
    bytes.push_back(static_cast<std::uint8_t>(type));
    bytes.insert(bytes.end(), body.begin(), body.end());
  }
  void text(char type, std::string_view s) { message(type, {s.begin(), s.end()}); }
  template <typename T>
  void keyed(char type, std::string_view key, T value, std::optional<std::uint8_t> first = std::nullopt) {
    std::vector<std::uint8_t> b;
    if (first) b.push_back(*first);
    b.push_back(static_cast<std::uint8_t>(key.size()));
    put(b, key);
    put(b, value);
    message(type, b);
  }
  void subscribe(std::uint16_t id, std::string_view name, std::uint8_t multi_id = 0) {
    std::vector<std::uint8_t> b{multi_id};
    put<std::uint16_t>(b, id);
    put(b, name);
    message('A', b);
  }
  void appended_offset(std::size_t i) {  // the next message starts appended data section i
    const std::uint64_t offset = bytes.size();
    std::memcpy(bytes.data() + 16 + 3 + 16 + 8 * i, &offset, sizeof offset);
  }
};

std::vector<std::uint8_t> record(std::uint16_t id, std::uint64_t t, std::initializer_list<float> floats) {
  std::vector<std::uint8_t> b;
  Writer::put<std::uint16_t>(b, id);
  Writer::put<std::uint64_t>(b, t);
  for (float f : floats) Writer::put<float>(b, f);
  return b;
}

std::vector<std::uint8_t> sensor_combined(std::uint64_t t, float gx, std::int32_t relative, float az, bool padding) {
  std::vector<std::uint8_t> b = record(0, t, {gx, 0.f, 0.f});
  Writer::put<std::int32_t>(b, relative);
  for (float f : {0.f, 0.f, az}) Writer::put<float>(b, f);
  if (padding) b.insert(b.end(), 4, 0);  // the trailing padding may be left out
  return b;
}

constexpr std::uint64_t kT0 = 1'000'000;

// 100 sensor_combined records at 250 Hz (record 50's accelerometer invalid), one more in appended data; 40
// attitudes at 100 Hz turning about z at 1 rad/s; 20 local positions at 50 Hz (record 7 without a horizontal fix);
// strings, a dropout, a sync, a parameter change, an unknown message type, a nested format with padding.
Writer synthetic() {
  Writer w(1);
  w.keyed('I', "char[3] ver_hw", std::string_view("FMU"));
  w.keyed('I', "int32_t time_ref_utc", std::int32_t{0});
  w.keyed('M', "char[5] console", std::string_view("hello"), std::uint8_t{0});
  w.keyed('M', "char[6] console", std::string_view(" world"), std::uint8_t{1});
  w.keyed('P', "float MC_ROLL_P", 6.5f);
  w.keyed('P', "int32_t SYS_AUTOSTART", std::int32_t{4001});
  w.keyed('Q', "float MC_ROLL_P", 7.0f, std::uint8_t{3});
  w.text('F', "vec3:float x;float y;float z;");
  w.text('F', "nested_topic:uint64_t timestamp;vec3[2] v;uint8_t[3] _padding0;int8_t last;uint8_t[4] _padding1;");
  w.text('F',
         "sensor_combined:uint64_t timestamp;float[3] gyro_rad;int32_t accelerometer_timestamp_relative;"
         "float[3] accelerometer_m_s2;uint8_t[4] _padding0;");
  w.text('F', "vehicle_attitude:uint64_t timestamp;float[4] q;");
  w.text('F',
         "vehicle_local_position:uint64_t timestamp;float x;float y;float z;float vx;float vy;float vz;"
         "bool xy_valid;bool z_valid;bool v_xy_valid;bool v_z_valid;");
  w.subscribe(0, "sensor_combined");
  w.subscribe(1, "vehicle_attitude");
  w.subscribe(2, "vehicle_local_position");
  w.subscribe(3, "nested_topic", 2);
  std::vector<std::uint8_t> nested = record(3, kT0, {1, 2, 3, 4, 5, 6});
  nested.insert(nested.end(), {0, 0, 0, static_cast<std::uint8_t>(-7)});  // trailing _padding1 left out
  w.message('D', nested);
  for (int i = 0; i < 100; ++i) {
    const std::uint64_t t = kT0 + 4000 * i;
    w.message('D', sensor_combined(t, 0.01f * i, i == 50 ? 0x7fffffff : -100, -9.81f, i % 2 == 0));
    if (i % 10 == 0) {
      for (int k = i / 10 * 4; k < i / 10 * 4 + 4; ++k) {
        const double yaw = 0.01 * k;
        w.message('D', record(1, kT0 + 10'000 * k, {float(std::cos(yaw / 2)), 0.f, 0.f, float(std::sin(yaw / 2))}));
      }
    }
    if (i % 5 == 1) {
      const int k = i / 5;
      std::vector<std::uint8_t> lp = record(2, kT0 + 5000 + 20'000 * k, {0.1f * k, 0.f, -1.f, 5.f, 0.f, 0.f});
      lp.insert(lp.end(), {std::uint8_t(k != 7), 1, 1, 1});
      w.message('D', lp);
    }
    if (i == 20) {
      std::vector<std::uint8_t> s{'6'};
      Writer::put<std::uint64_t>(s, kT0 + 80'000);
      Writer::put(s, std::string_view("[commander] Takeoff detected"));
      w.message('L', s);
      std::vector<std::uint8_t> c{'4'};
      Writer::put<std::uint16_t>(c, 7);
      Writer::put<std::uint64_t>(c, kT0 + 81'000);
      Writer::put(c, std::string_view("tagged"));
      w.message('C', c);
      w.message('S', {0x2f, 0x73, 0x13, 0x20, 0x25, 0x0c, 0xbb, 0x12});
      w.message('O', {25, 0});
      w.keyed('P', "float MC_ROLL_P", 6.0f);
      w.message('Z', {1, 2, 3});  // a message type from the future: skipped
    }
  }
  w.message('R', {3, 0});
  w.appended_offset(0);
  w.keyed('M', "char[4] hardfault", std::string_view("boom"), std::uint8_t{0});
  w.message('D', sensor_combined(kT0 + 4000 * 100, 1.0f, 0, -9.81f, true));
  return w;
}

class UlogImport : public ::testing::Test {
 protected:
  fs::path dir_ = fs::temp_directory_path() / ("imubridge_ulog_import_" + std::to_string(::getpid()));
  void SetUp() override { fs::create_directories(dir_); }
  void TearDown() override { fs::remove_all(dir_); }

  fs::path write(const std::vector<std::uint8_t>& bytes, const std::string& name = "log.ulg") {
    const fs::path path = dir_ / name;
    std::ofstream(path, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    return path;
  }
};

TEST(UlogReader, ReadsEveryMessageTypeOfTheSpecification) {
  const Writer w = synthetic();
  const ulog::Log log = ulog::parse(w.bytes);
  EXPECT_EQ(log.version, 1);
  EXPECT_EQ(log.start_us, 1000u);
  EXPECT_TRUE(log.data_appended);
  EXPECT_FALSE(log.damage);
  EXPECT_EQ(log.info.at("ver_hw"), "FMU");
  EXPECT_EQ(log.info.at("time_ref_utc"), 0);
  EXPECT_EQ(log.multi_info.at("console"), nlohmann::json::array({"hello world"}));
  EXPECT_EQ(log.multi_info.at("hardfault"), nlohmann::json::array({"boom"}));  // from appended data
  EXPECT_EQ(log.params.at("MC_ROLL_P"), 6.5);
  EXPECT_EQ(log.params.at("SYS_AUTOSTART"), 4001);
  EXPECT_EQ(log.default_params.at("MC_ROLL_P"), (nlohmann::json{{"value", 7.0}, {"system", true}, {"airframe", true}}));
  ASSERT_EQ(log.param_changes.size(), 1u);
  EXPECT_EQ(log.param_changes[0].value, 6.0);
  EXPECT_EQ(log.param_changes[0].after_us, kT0 + 110'000);  // the attitude written just before it
  ASSERT_EQ(log.strings.size(), 2u);
  EXPECT_EQ(log.strings[0].text, "[commander] Takeoff detected");
  EXPECT_EQ(log.strings[0].level, '6');
  EXPECT_EQ(log.strings[1].tag, 7);
  EXPECT_EQ(log.strings[1].timestamp_us, kT0 + 81'000);
  ASSERT_EQ(log.dropouts.size(), 1u);
  EXPECT_EQ(log.dropouts[0].duration_ms, 25);
  EXPECT_EQ(log.syncs, 1u);
  EXPECT_EQ(log.appended_messages, 2u);
  EXPECT_EQ(log.skipped.at("unknown message type"), 1u);

  const ulog::Topic* nested = log.topic("nested_topic", 2);
  ASSERT_NE(nested, nullptr);
  EXPECT_EQ(nested->record_size, 8 + 24 + 3 + 1 + 4);
  ASSERT_EQ(nested->size(), 1u);
  EXPECT_EQ(nested->value(0, *nested->leaf("v[1].y")), 5);
  EXPECT_EQ(nested->value(0, *nested->leaf("last")), -7);
  EXPECT_FALSE(nested->leaf("_padding0"));

  const ulog::Topic* combined = log.topic("sensor_combined");
  ASSERT_NE(combined, nullptr);
  EXPECT_EQ(combined->size(), 101u);
  EXPECT_EQ(combined->appended_records, 1u);
  EXPECT_EQ(combined->timestamp(100), kT0 + 400'000);
  EXPECT_FLOAT_EQ(combined->value(99, *combined->leaf("gyro_rad[0]")), 0.99f);
  EXPECT_EQ(log.topic("vehicle_attitude")->size(), 40u);
  EXPECT_EQ(log.topic("vehicle_local_position")->size(), 20u);
}

TEST(UlogReader, RefusesWhatItCannotReadInOneLine) {
  const auto error = [](const std::vector<std::uint8_t>& bytes) -> std::string {
    try {
      ulog::parse(bytes);
    } catch (const ulog::ParseError& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_EQ(error({'n', 'o', 't'}), "not a ULog file (no ULog magic in the first 7 bytes)");
  EXPECT_EQ(error(Writer(2).bytes), "the log sets incompatible flag bits this reader does not know");
  Writer bad;
  bad.text('F', "sensor_combined uint64_t timestamp;");
  EXPECT_EQ(error(bad.bytes), "format definition without a name: \"sensor_combined uint64_t timestamp;\"");
  Writer field;
  field.text('F', "t:uint64_t timestamp;float[x] y;");
  EXPECT_EQ(error(field.bytes), "format t: malformed field \"float[x] y\"");
  Writer loop;
  loop.text('F', "a:uint64_t timestamp;b inner;");
  loop.text('F', "b:a inner;");
  loop.subscribe(0, "a");
  EXPECT_EQ(error(loop.bytes), "format b nests itself");
  for (const std::string& message : {error(bad.bytes), error(loop.bytes)}) {
    EXPECT_EQ(message.find('\n'), std::string::npos);
  }
}

// Cut anywhere, the file is refused in one line (in the definitions) or read up to the cut (in the data).
TEST(UlogReader, ReadsATruncatedFileUpToTheDamage) {
  const Writer w = synthetic();
  std::size_t damaged = 0, refused = 0;
  for (std::size_t size = 0; size < w.bytes.size(); size += 7) {
    const std::span<const std::uint8_t> cut(w.bytes.data(), size);
    try {
      const ulog::Log log = ulog::parse(cut);
      if (log.damage) ++damaged;
    } catch (const ulog::ParseError&) {
      ++refused;
    }
  }
  EXPECT_GT(damaged, 100u);
  EXPECT_GT(refused, 10u);
  const ulog::Log half = ulog::parse(std::span(w.bytes.data(), w.bytes.size() / 2 + 1));
  ASSERT_TRUE(half.damage);
  EXPECT_NE(half.damage->find("cut short at byte"), std::string::npos) << *half.damage;
  EXPECT_GT(half.topic("sensor_combined")->size(), 10u);
}

TEST_F(UlogImport, SamplesReferenceEventsAndMetadata) {
  store::Store store(dir_ / "import.db");
  ReportedProblems problems;
  const auto r = import_ulog(store, {.file = write(synthetic().bytes), .on_problem = problems.callback()});
  EXPECT_EQ(r.imu_source, "sensor_combined");
  EXPECT_EQ(r.samples, 100u);
  EXPECT_EQ(problems.counts(ProblemKind::skipped, "sensor_combined records"),
            (std::map<std::string, std::uint64_t>{{"no accelerometer sample (relative timestamp invalid)", 1}}));
  EXPECT_EQ(r.first_us, kT0);
  EXPECT_EQ(r.last_us, kT0 + 400'000);
  EXPECT_TRUE(r.data_appended);
  EXPECT_EQ(r.dropouts, 1u);
  EXPECT_EQ(r.dropout_ms, 25u);
  EXPECT_EQ(r.log_events, 2u);
  EXPECT_FALSE(r.axes.mismatch);

  const auto s = stored_samples(store, r.session);
  ASSERT_EQ(s.size(), 100u);
  EXPECT_EQ(s[0].device_time_us, static_cast<std::int64_t>(kT0));
  EXPECT_EQ(s[0].recv_mono_ns, static_cast<std::int64_t>(kT0) * 1000);
  EXPECT_NEAR(s[0].accel[2], -9.81, 2.5e-3);
  EXPECT_EQ(s[50].device_time_us, static_cast<std::int64_t>(kT0 + 4000 * 51));  // record 50 skipped
  EXPECT_EQ(s[50].seq, 50u);
  EXPECT_NEAR(s[99].gyro[0], 1.0, 0.55e-3);  // the appended record
  EXPECT_EQ(s[99].device_time_us, static_cast<std::int64_t>(kT0 + 400'000));

  const auto ref = stored_reference(store, r.session);
  EXPECT_EQ(r.reference_rows, 19u);
  ASSERT_EQ(ref.size(), 19u);
  EXPECT_EQ(
      problems.counts(ProblemKind::skipped, "reference rows").at("horizontal position not valid (xy_valid false)"), 1u);
  EXPECT_EQ(ref[0].t_ns, static_cast<std::int64_t>(kT0 + 5000) * 1000);
  EXPECT_NEAR(ref[0].quat_wxyz[0], std::cos(0.0025), 1e-6);  // halfway between yaw 0 and 0.01
  EXPECT_NEAR(ref[0].quat_wxyz[3], std::sin(0.0025), 1e-6);
  EXPECT_NEAR(ref[1].position[0], 0.1, 1e-6);
  EXPECT_EQ(ref[1].position[2], -1);
  ASSERT_TRUE(ref[1].velocity);
  EXPECT_EQ((*ref[1].velocity)[0], 5);

  const auto log = stored_events(store, r.session, "log");
  ASSERT_EQ(log.size(), 2u);
  EXPECT_EQ(log[0].detail, "info: [commander] Takeoff detected");
  EXPECT_EQ(log[0].mono_ns, static_cast<std::int64_t>(kT0 + 80'000) * 1000);
  EXPECT_EQ(log[1].detail, "warning (tag 7): tagged");
  const auto dropout = stored_events(store, r.session, "dropout");
  ASSERT_EQ(dropout.size(), 1u);
  EXPECT_EQ(dropout[0].detail, "the logger dropped 25 ms of data");

  const auto c = session_config(store, r.session).at("import");
  EXPECT_EQ(c.at("format"), "ulog");
  EXPECT_EQ(c.at("params").at("SYS_AUTOSTART"), 4001);
  EXPECT_EQ(c.at("info").at("ver_hw"), "FMU");
  EXPECT_EQ(c.at("param_changes").size(), 1u);
  EXPECT_EQ(c.at("data_appended"), true);
}

TEST_F(UlogImport, NoReferenceWhenAskedAndAxesAsDeclared) {
  store::Store store(dir_ / "import.db");
  const auto r = import_ulog(store, {.file = write(synthetic().bytes), .imu_axes = "flu", .reference = false});
  EXPECT_EQ(r.reference_rows, 0u);
  EXPECT_TRUE(stored_reference(store, r.session).empty());
  EXPECT_TRUE(r.axes.mismatch);  // gravity on -z at rest: FRD, not FLU
}

TEST_F(UlogImport, ImportsATruncatedFileUpToTheDamageAndSaysSo) {
  const Writer w = synthetic();
  store::Store store(dir_ / "import.db");
  ReportedProblems problems;
  const fs::path cut = write({w.bytes.begin(), w.bytes.begin() + w.bytes.size() * 3 / 4});
  const auto r = import_ulog(store, {.file = cut, .on_problem = problems.callback()});
  const auto damage = problems.of(ProblemKind::damaged);
  ASSERT_EQ(damage.size(), 1u);
  EXPECT_EQ(damage[0].count, 1u);
  EXPECT_EQ(damage[0].what, "stretch of " + cut.string());
  EXPECT_NE(damage[0].why.find("cut short"), std::string::npos) << damage[0].why;
  EXPECT_TRUE(damage[0].why.ends_with("; everything before it is imported")) << damage[0].why;
  EXPECT_GT(r.samples, 40u);
  EXPECT_LT(r.samples, 100u);
  EXPECT_EQ(stored_samples(store, r.session).size(), r.samples);  // every good record before the damage
  const auto damaged = stored_events(store, r.session, "import_damaged");
  ASSERT_EQ(damaged.size(), 1u);
  EXPECT_NE(damaged[0].detail.find("cut short"), std::string::npos);
  // Cut inside the definitions: one line, nothing written.
  EXPECT_THROW(import_ulog(store, {.file = write({w.bytes.begin(), w.bytes.begin() + 200}, "short.ulg")}),
               std::invalid_argument);
  EXPECT_EQ(store.sessions().size(), 1u);
  EXPECT_THROW(import_ulog(store, {.file = dir_ / "absent.ulg"}), std::invalid_argument);
}

// What the PX4 sample logs hold: counts and values read with the reader, checked against what pyulog's test data
// and the logs' own info say (hardware, airframe).
struct Expected {
  const char* file;
  std::size_t topics, params;
  std::uint64_t samples, first_us, last_us;
  std::array<double, 6> first, last;  // accel xyz, gyro xyz
  std::uint64_t dropouts, dropout_ms, strings, local_positions;
  const char* ver_hw;
  std::int64_t autostart;
  std::size_t hardfaults;  // 'M' hardfault_plain values, in appended data
  int flights;             // airborne intervals by vehicle_land_detected; -1: the log has no land detector record
  std::uint64_t takeoff_us, landing_us;  // the first one's
};

// clang-format off
const Expected kLogs[] = {
    {"sample.ulg", 43, 493, 17070, 112614307, 181493506,
     {1.10714173, -0.486477524, -9.63039494, -0.00192494364, -0.00331021356, -0.00323856669},
     {1.14002633, -0.441030651, -9.63232517, -0.00137469545, -0.0025773237, -0.0037138944}, 4, 119, 4, 678,
     "AUAV_X21", 10020, 0, -1, 0, 0},
    {"sample_appended_multiple.ulg", 44, 750, 2373, 12262822, 21880422,
     {0.540145457, 0.321722984, -9.93630314, 0.0032860369, 0.00932722911, 0.00394874206},
     {0.541375518, 0.30004558, -9.92365265, 0.0589871854, 0.0317205563, 0.0122601017}, 0, 0, 1, 95,
     "PX4FMU_V4PRO", 4001, 3, 0, 0, 0},
    {"sample_log_small.ulg", 72, 980, 1298, 20326716, 26822868,
     {0.00124580564, -0.154344976, -9.63424301, 0.00296838349, 0.00364623987, 0.000942496117},
     {-0.0100537231, -0.163725868, -9.56682873, 0.00388484122, -0.00303378864, 0.000779201684}, 1, 30, 3, 636,
     "CUBEPILOT_CUBEORANGE", 13014, 0, 1, 22673775, 23822439},
};
// clang-format on

// A real PX4 log in which every topic stops for about 37 s (43 to 80 s) with no dropout message: the hole is a gap
// event with its span, and the samples on either side are all imported.
TEST_F(UlogImport, AHoleInARealLogIsAGapEvent) {
  const fs::path path = kShared / "x500v2_unregistered_msg_id.ulg";
  if (!fs::exists(path)) GTEST_SKIP() << "no " << path << " (it is in ../shared only)";
  store::Store store(dir_ / "x500.db");
  const auto r = import_ulog(store, {.file = path});
  EXPECT_EQ(r.dropouts, 0u);
  ASSERT_EQ(r.gaps.holes.size(), 1u);
  const Gap& hole = r.gaps.holes[0];
  const double from_s = static_cast<double>(hole.from_ns - r.gaps.session_start_ns) * 1e-9;
  const double to_s = static_cast<double>(hole.to_ns - r.gaps.session_start_ns) * 1e-9;
  EXPECT_GT(from_s, 40);
  EXPECT_LT(from_s, 46);
  EXPECT_GT(to_s, 77);
  EXPECT_LT(to_s, 83);
  EXPECT_GT(hole.seconds(), 34);
  const auto gap = stored_events(store, r.session, "gap");
  ASSERT_EQ(gap.size(), 1u);
  EXPECT_EQ(gap[0].mono_ns, hole.from_ns);
  EXPECT_TRUE(gap[0].detail.starts_with("no IMU sample for 3")) << gap[0].detail;
  const auto s = stored_samples(store, r.session);
  EXPECT_TRUE(
      std::any_of(s.begin(), s.end(), [&](const protocol::Sample& x) { return x.recv_mono_ns > hole.from_ns; }));
}

TEST_F(UlogImport, ThePx4SampleLogs) {
  std::size_t imported = 0;
  for (const Expected& e : kLogs) {
    SCOPED_TRACE(e.file);
    fs::path path = kData / e.file;
    if (!fs::exists(path)) path = kShared / e.file;
    if (!fs::exists(path)) continue;  // sample.ulg (4 MB) is only in ../shared; a clean clone has the others
    const ulog::Log log = ulog::read_file(path);
    EXPECT_EQ(log.topics.size(), e.topics);
    EXPECT_EQ(log.params.size(), e.params);
    EXPECT_EQ(log.params.at("SYS_AUTOSTART"), e.autostart);
    EXPECT_EQ(log.info.at("ver_hw"), e.ver_hw);
    EXPECT_FALSE(log.damage);
    EXPECT_EQ(log.data_appended, e.hardfaults > 0);
    if (e.hardfaults > 0) {
      EXPECT_EQ(log.appended_messages, e.hardfaults);
      EXPECT_EQ(log.multi_info.at("hardfault_plain").size(), e.hardfaults);
    }

    store::Store store(dir_ / (std::string(e.file) + ".db"));
    ReportedProblems problems;
    const auto r = import_ulog(store, {.file = path, .on_problem = problems.callback()});
    EXPECT_EQ(r.imu_source, "sensor_combined");
    EXPECT_EQ(r.samples, e.samples);
    EXPECT_TRUE(problems.of(ProblemKind::skipped, "sensor_combined").empty());
    EXPECT_TRUE(problems.of(ProblemKind::clipped).empty());
    EXPECT_TRUE(problems.of(ProblemKind::damaged).empty());
    EXPECT_EQ(r.first_us, e.first_us);
    EXPECT_EQ(r.last_us, e.last_us);
    EXPECT_EQ(r.dropouts, e.dropouts);
    EXPECT_EQ(r.dropout_ms, e.dropout_ms);
    EXPECT_EQ(r.log_events, e.strings);
    EXPECT_FALSE(r.axes.mismatch);  // gravity on -z: FRD, as declared
    // PX4's land detector: sample.ulg subscribed to it and logged no record (unknown), the appended log's one record
    // says landed, the small log lifted off once for about a second.
    ASSERT_EQ(r.airborne.has_value(), e.flights >= 0);
    if (r.airborne) {
      ASSERT_EQ(r.airborne->size(), static_cast<std::size_t>(e.flights));
      if (e.flights > 0) {
        EXPECT_EQ(r.airborne->front().from_us, e.takeoff_us);
        EXPECT_EQ(r.airborne->front().to_us, e.landing_us);
      }
    }
    EXPECT_EQ(stored_events(store, r.session, "takeoff").size(), static_cast<std::size_t>(std::max(e.flights, 0)));
    EXPECT_EQ(stored_events(store, r.session, "landing").size(), static_cast<std::size_t>(std::max(e.flights, 0)));
    const auto s = stored_samples(store, r.session);
    ASSERT_EQ(s.size(), e.samples);
    EXPECT_EQ(s.front().device_time_us, static_cast<std::int64_t>(e.first_us));
    EXPECT_EQ(s.back().device_time_us, static_cast<std::int64_t>(e.last_us));
    EXPECT_EQ(s.back().seq, e.samples - 1);
    for (int i = 0; i < 3; ++i) {  // within half a count of the frames' resolution
      EXPECT_NEAR(s.front().accel[i], e.first[i], 2.5e-3);
      EXPECT_NEAR(s.back().accel[i], e.last[i], 2.5e-3);
      EXPECT_NEAR(s.front().gyro[i], e.first[3 + i], 0.55e-3);
      EXPECT_NEAR(s.back().gyro[i], e.last[3 + i], 0.55e-3);
    }
    // None of the three has a horizontal fix (bench and indoor logs: no GPS), so no reference row is true.
    EXPECT_EQ(r.reference_rows, 0u);
    EXPECT_EQ(
        problems.counts(ProblemKind::skipped, "reference rows").at("horizontal position not valid (xy_valid false)"),
        e.local_positions);
    EXPECT_EQ(stored_events(store, r.session, "dropout").size(), e.dropouts);
    EXPECT_EQ(stored_events(store, r.session, "log").size(), e.strings);
    const auto c = session_config(store, r.session).at("import");
    EXPECT_EQ(c.at("params").size(), e.params);
    EXPECT_EQ(c.at("info").at("ver_hw"), e.ver_hw);
    ++imported;
  }
  if (imported == 0) GTEST_SKIP() << "no PX4 sample log in " << kData << " or " << kShared;
  EXPECT_GE(imported, 2u);
}

}  // namespace
}  // namespace imubridge::importers
