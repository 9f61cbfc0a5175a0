// MAVLink telemetry logs: the reader on logs built here from a simulated flight with the project's own MAVLink
// encoder (sim::MavlinkTelemetry), damaged and garbage files, and the import's samples, IMU choice, reference and
// events against the simulator's truth.
#include "importers/tlog_import.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>

#include "importers/tlog.hpp"
#include "protocol/mavlink.hpp"
#include "replay/replayer.hpp"
#include "sim/frame_encoder.hpp"
#include "sim/scenario.hpp"
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
namespace mav = protocol::mavlink;
using Bytes = std::vector<std::uint8_t>;

constexpr std::uint64_t kEpochUs = 1'704'067'200'000'000;  // 2024-01-01 00:00:00 UTC

std::uint64_t us(double seconds) { return static_cast<std::uint64_t>(std::llround(seconds * 1e6)); }

// A simulated flight's telemetry as a tlog, each sample's frames stamped with its time. `extra` may add frames of
// its own for a sample (framed by the same sender, so the sequence stays whole).
struct Flight {
  std::vector<sim::SimSample> samples;
  Bytes tlog;
  std::size_t records = 0;
};

template <typename Extra>
Flight fly(double seconds, Extra extra) {
  Flight f;
  f.samples = sim::simulate(sim::make_scenario("paper", 3, seconds));
  sim::MavlinkTelemetry telemetry;
  std::vector<Bytes> frames;
  for (const sim::SimSample& s : f.samples) {
    frames.clear();
    telemetry.encode(s, frames);
    extra(s, telemetry, frames);
    for (const Bytes& frame : frames) tlog::append_record(f.tlog, kEpochUs + us(s.time_s), frame);
    f.records += frames.size();
  }
  return f;
}

Flight fly(double seconds = 2.0) {
  return fly(seconds, [](const sim::SimSample&, sim::MavlinkTelemetry&, std::vector<Bytes>&) {});
}

// SCALED_IMU2 of the sample's measured values, in its units (mG, mrad/s), rounded to them.
mav::ScaledImu2 scaled_imu2(const sim::SimSample& s) {
  const auto count = [](double v) { return static_cast<std::int16_t>(std::lround(v)); };
  const auto& m = s.measured;
  return {.time_boot_ms = static_cast<std::uint32_t>(std::llround(s.time_s * 1e3)),
          .xacc = count(m.accel.x() / 9.80665 * 1000),
          .yacc = count(m.accel.y() / 9.80665 * 1000),
          .zacc = count(m.accel.z() / 9.80665 * 1000),
          .xgyro = count(m.gyro.x() * 1000),
          .ygyro = count(m.gyro.y() * 1000),
          .zgyro = count(m.gyro.z() * 1000)};
}

class TlogImport : public ::testing::Test {
 protected:
  test::TempDir dir_;

  fs::path write(const Bytes& bytes, const std::string& name = "flight.tlog") { return dir_.write(name, bytes); }
};

std::string parse_error(Bytes bytes) {
  try {
    tlog::parse(std::move(bytes));
  } catch (const tlog::ParseError& e) {
    return e.what();
  }
  return "";
}

TEST(TlogReader, ReadsEveryRecordOfASimulatedFlight) {
  const Flight f = fly(1.0);
  const tlog::Log log = tlog::parse(f.tlog);
  ASSERT_EQ(log.records.size(), f.records);
  // HIGHRES_IMU for every sample, ATTITUDE and LOCAL_POSITION_NED for every tenth.
  EXPECT_EQ(f.records, f.samples.size() + 2 * ((f.samples.size() + 9) / 10));
  EXPECT_TRUE(log.damage.empty());
  EXPECT_FALSE(log.damage_summary());
  EXPECT_EQ(log.unverified, 0u);
  EXPECT_EQ(log.records[0].offset, 0u);
  EXPECT_EQ(log.records[0].time_us, kEpochUs);
  EXPECT_EQ(log.records.back().time_us, kEpochUs + us(f.samples.back().time_s));
  // The frames are the bytes after each time, whole: together with the times they are the file.
  std::size_t bytes = 0;
  for (const tlog::Record& r : log.records) {
    EXPECT_EQ(r.offset, bytes);
    EXPECT_EQ(mav::check_frame(log.frame(r)).status, mav::FrameCheck::Status::frame);
    bytes += tlog::kTimeSize + r.size;
  }
  EXPECT_EQ(bytes, f.tlog.size());
}

TEST(TlogReader, WhatIsNotATlogIsRefusedInOneLine) {
  const Flight f = fly(0.5);
  Bytes raw;  // the same frames without their times: a MAVLink capture, not a log
  const tlog::Log log = tlog::parse(f.tlog);
  for (const tlog::Record& r : log.records) raw.insert(raw.end(), log.frame(r).begin(), log.frame(r).end());
  std::mt19937 rng(5);
  Bytes noise(100'000);
  for (auto& b : noise) b = static_cast<std::uint8_t>(rng());
  const std::string text = "timestamp,x,y,z\n1,2,3,4\n";
  Bytes late(2000, 0);  // a valid record, but after 2000 bytes of something else
  late.insert(late.end(), f.tlog.begin(), f.tlog.end());
  for (const Bytes& bytes : {raw, noise, Bytes(text.begin(), text.end()), Bytes{}, late}) {
    const std::string error = parse_error(bytes);
    EXPECT_TRUE(error.starts_with("not a MAVLink telemetry log (tlog)")) << error;
    EXPECT_EQ(error.find('\n'), std::string::npos);
  }
  EXPECT_EQ(parse_error({}), "not a MAVLink telemetry log (tlog): the file is empty");
}

// Cut anywhere inside the last record, the file reads up to it and says how much is cut and where.
TEST(TlogReader, TheLastRecordCutShortIsDamageAndTheRestIsRead) {
  const Flight f = fly(0.5);
  const tlog::Log whole = tlog::parse(f.tlog);
  const tlog::Record& last = whole.records.back();
  for (std::size_t keep = 1; keep < tlog::kTimeSize + last.size; ++keep) {
    SCOPED_TRACE(keep);
    const tlog::Log log = tlog::parse(Bytes(f.tlog.begin(), f.tlog.begin() + static_cast<long>(last.offset + keep)));
    ASSERT_EQ(log.records.size(), whole.records.size() - 1);
    ASSERT_EQ(log.damage.size(), 1u);
    EXPECT_EQ(log.damage[0].offset, last.offset);
    EXPECT_EQ(log.damage[0].bytes, keep);
    EXPECT_EQ(log.damage[0].record, whole.records.size() - 1);
    EXPECT_TRUE(log.damage[0].what.starts_with("the last record, cut short (" + std::to_string(keep) + " bytes"))
        << log.damage[0].what;
  }
}

// A record whose frame is damaged costs its own bytes only: reading goes on at the next record.
TEST(TlogReader, ADamagedRecordInTheMiddleIsSkippedAndReadingGoesOn) {
  const Flight f = fly(0.5);
  const tlog::Log whole = tlog::parse(f.tlog);
  const tlog::Record& hit = whole.records[40];
  const tlog::Record& other = whole.records[70];
  Bytes bytes = f.tlog;
  bytes[hit.offset + tlog::kTimeSize + 15] ^= 0x04;  // a payload bit: its CRC fails
  bytes[other.offset + tlog::kTimeSize] = 0x55;      // its STX: no frame at all
  const tlog::Log log = tlog::parse(bytes);
  EXPECT_EQ(log.records.size(), whole.records.size() - 2);
  ASSERT_EQ(log.damage.size(), 2u);
  EXPECT_EQ(log.damage[0].offset, hit.offset);
  EXPECT_EQ(log.damage[0].bytes, tlog::kTimeSize + hit.size);
  EXPECT_EQ(log.damage[0].record, 40u);
  EXPECT_EQ(log.damage[0].what, "a frame that fails its CRC");
  EXPECT_EQ(log.damage[1].offset, other.offset);
  EXPECT_EQ(log.damage[1].bytes, tlog::kTimeSize + other.size);
  EXPECT_EQ(log.damage[1].what, "not a MAVLink frame");
  EXPECT_EQ(log.records[40].offset, whole.records[41].offset);
  EXPECT_EQ(log.damaged_bytes(), 2 * tlog::kTimeSize + hit.size + other.size);
  const std::string summary = log.damage_summary().value();
  EXPECT_TRUE(summary.starts_with("2 damaged stretches, " + std::to_string(log.damaged_bytes()) + " bytes: "))
      << summary;
  EXPECT_NE(summary.find("at byte " + std::to_string(hit.offset) + " (after record 40)"), std::string::npos) << summary;
}

// Well-formed frames nothing here can check are records, not damage: a MAVLink 2 frame of an id in no dialect known
// here, and a MAVLink 1 frame of a known id (ATTITUDE, 28 bytes) at a length its message cannot have (another
// dialect's or an older version's message of that id). Each is counted by id and said to be what it is.
TEST_F(TlogImport, ValidFramesOfUnknownIdsAndLayoutsAreCountedAsSuchNotAsDamage) {
  std::uint8_t seq = 0;
  const Flight f = fly(1.0, [&](const sim::SimSample&, sim::MavlinkTelemetry&, std::vector<Bytes>& frames) {
    if (seq % 10 == 0) {
      Bytes unknown, old;
      mav::encode(mav::make_message(42424, Bytes(12, 7), {.seq = seq, .sysid = 1, .compid = 191}), unknown);
      mav::encode(mav::make_message(30, Bytes(20, 3), {.version = 1, .seq = seq, .sysid = 1, .compid = 192}), old);
      frames.push_back(unknown);
      frames.push_back(old);
    }
    ++seq;
  });
  const std::uint64_t each = (f.samples.size() + 9) / 10;
  const tlog::Log log = tlog::parse(f.tlog);
  EXPECT_TRUE(log.damage.empty());
  EXPECT_EQ(log.records.size(), f.records);
  EXPECT_EQ(log.unknown_ids, (std::map<std::uint32_t, std::uint64_t>{{42424, each}}));
  EXPECT_EQ(log.other_layout_ids, (std::map<std::uint32_t, std::uint64_t>{{30, each}}));
  EXPECT_EQ(log.unverified, 2 * each);
  const std::string n = std::to_string(each);
  EXPECT_EQ(log.unverified_summary().value(),
            n + " frames (ids 42424: " + n + ") of message ids no dialect here knows; " + n + " frames (ids 30: " + n +
                ") of known ids at a MAVLink 1 length their message cannot have (another dialect or version)");

  store::Store store(dir_ / "import.db");
  ReportedProblems problems;
  const auto r = import_tlog(store, {.file = write(f.tlog), .on_problem = problems.callback()});
  EXPECT_TRUE(problems.of(ProblemKind::damaged).empty());
  EXPECT_EQ(r.unverified, 2 * each);
  EXPECT_EQ(r.unverified_summary, log.unverified_summary());
  EXPECT_EQ(r.samples, f.samples.size());
  EXPECT_TRUE(stored_events(store, r.session, "import_damaged").empty());
  const auto c = session_config(store, r.session).at("import");
  EXPECT_EQ(c.at("unknown_ids").at("42424"), each);
  EXPECT_EQ(c.at("other_layout_ids").at("30"), each);
}

// The flight through the import: every HIGHRES_IMU a sample with the values sent, ATTITUDE with
// LOCAL_POSITION_NED the simulator's truth as the reference, and the session replays to the same samples.
TEST_F(TlogImport, ASimulatedFlightGivesTheSimulatorsSamplesAndTruth) {
  const Flight f = fly(2.0);
  store::Store store(dir_ / "import.db");
  ReportedProblems problems;
  const auto r = import_tlog(store, {.file = write(f.tlog), .on_problem = problems.callback()});
  EXPECT_EQ(r.imu_source, "HIGHRES_IMU id 0 from system 1, component 1");
  EXPECT_EQ(r.samples, f.samples.size());
  EXPECT_EQ(r.records, f.records);
  EXPECT_TRUE(problems.all.empty());
  EXPECT_FALSE(r.axes.mismatch);
  EXPECT_EQ(r.first_us, kEpochUs);
  EXPECT_EQ(r.reference_source, "LOCAL_POSITION_NED + ATTITUDE from system 1, component 1");

  const auto s = stored_samples(store, r.session);
  ASSERT_EQ(s.size(), f.samples.size());
  for (std::size_t i = 0; i < s.size(); ++i) {
    const sim::SimSample& want = f.samples[i];
    ASSERT_EQ(s[i].device_time_us, std::llround(want.time_s * 1e6)) << i;
    ASSERT_EQ(s[i].recv_mono_ns, static_cast<std::int64_t>(kEpochUs + us(want.time_s)) * 1000) << i;
    for (int a = 0; a < 3; ++a) {  // HIGHRES_IMU carries floats: the value sent, to a float's precision
      ASSERT_EQ(s[i].accel[a], static_cast<float>(want.measured.accel[a])) << i;
      ASSERT_EQ(s[i].gyro[a], static_cast<float>(want.measured.gyro[a])) << i;
    }
  }

  const auto ref = stored_reference(store, r.session);
  ASSERT_EQ(ref.size(), (f.samples.size() + 9) / 10);
  EXPECT_EQ(r.reference_rows, ref.size());
  for (std::size_t k = 0; k < ref.size(); ++k) {
    const sim::TrueState& truth = f.samples[10 * k].truth;
    EXPECT_EQ(ref[k].t_ns, static_cast<std::int64_t>(kEpochUs + us(f.samples[10 * k].time_s)) * 1000);
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR(ref[k].position[a], truth.position_ned[a], 1e-6 * (1 + std::abs(truth.position_ned[a])));
      ASSERT_TRUE(ref[k].velocity);
      EXPECT_NEAR((*ref[k].velocity)[a], truth.velocity_ned[a], 1e-6 * (1 + std::abs(truth.velocity_ned[a])));
    }
    // ATTITUDE's float Euler angles, back to the quaternion: the same rotation within a float's precision.
    const Eigen::Quaterniond got(ref[k].quat_wxyz[0], ref[k].quat_wxyz[1], ref[k].quat_wxyz[2], ref[k].quat_wxyz[3]);
    EXPECT_LT(got.angularDistance(truth.attitude), 1e-6) << k;
  }

  const auto c = session_config(store, r.session);
  EXPECT_EQ(c.at("import").at("format"), "tlog");
  EXPECT_EQ(c.at("import").at("messages").at("HIGHRES_IMU"), f.samples.size());
  EXPECT_EQ(c.at("links")[0].at("protocol"), "mavlink");
  EXPECT_EQ(c.at("links")[0].at("mavlink_imu").at("message"), "HIGHRES_IMU");

  // The stored chunks are the frames: replay decodes them as the import did.
  const replay::ReplayResult replayed = replay::replay_session(store, r.session, {});
  EXPECT_EQ(replayed.samples, f.samples.size());
}

// Three IMUs in one log: the one sending the most is imported, the others are counted and named; a replay keeps to
// the same one; --imu-message picks another, whose samples are in its own units.
TEST_F(TlogImport, TheImuWithTheMostMessagesIsImportedAndTheOthersNamed) {
  const Flight f = fly(1.0, [](const sim::SimSample& s, sim::MavlinkTelemetry& telemetry, std::vector<Bytes>& frames) {
    if (s.index % 2 == 0) frames.push_back(telemetry.frame(scaled_imu2(s)));
    if (s.index % 4 == 0) frames.push_back(telemetry.frame(mav::ScaledImu3{.time_boot_ms = 1, .zacc = -1000}));
  });
  store::Store store(dir_ / "import.db");
  const std::uint64_t n = f.samples.size(), n2 = (n + 1) / 2, n3 = (n + 3) / 4;
  ReportedProblems problems;
  const auto r = import_tlog(store, {.file = write(f.tlog), .on_problem = problems.callback()});
  EXPECT_EQ(r.imu_source, "HIGHRES_IMU id 0 from system 1, component 1");
  EXPECT_EQ(r.samples, n);
  EXPECT_EQ(r.imu_messages.at("SCALED_IMU2 from system 1, component 1"), n2);
  const std::map<std::string, std::uint64_t> skipped{
      {"SCALED_IMU2 from system 1, component 1: not the IMU imported", n2},
      {"SCALED_IMU3 from system 1, component 1: not the IMU imported", n3}};
  EXPECT_EQ(problems.counts(ProblemKind::skipped, "IMU messages"), skipped);
  EXPECT_EQ(stored_events(store, r.session, "import_skipped").size(), 2u);
  EXPECT_EQ(stored_samples(store, r.session).size(), n);
  EXPECT_EQ(replay::replay_session(store, r.session, {}).samples,
            n);  // not n + n2 + n3: the others stay out on replay too

  const auto second = import_tlog(store, {.file = write(f.tlog), .imu_message = "SCALED_IMU2"});
  EXPECT_EQ(second.imu_source, "SCALED_IMU2 from system 1, component 1");
  const auto s = stored_samples(store, second.session);
  ASSERT_EQ(s.size(), n2);
  for (std::size_t k = 0; k < s.size(); ++k) {
    const sim::SimSample& want = f.samples[2 * k];
    EXPECT_EQ(s[k].device_time_us, std::llround(want.time_s * 1e3) * 1000);
    for (int a = 0; a < 3; ++a) {  // within half a unit: 0.5 mG, 0.5 mrad/s
      EXPECT_NEAR(s[k].accel[a], want.measured.accel[a], 0.5e-3 * 9.80665 + 1e-12) << k;
      EXPECT_NEAR(s[k].gyro[a], want.measured.gyro[a], 0.5e-3 + 1e-12) << k;
    }
  }
  EXPECT_EQ(replay::replay_session(store, second.session, {}).samples, n2);
}

TEST_F(TlogImport, RawImuOnlyWithItsResolutions) {
  const Flight f = fly(0.5, [](const sim::SimSample& s, sim::MavlinkTelemetry& telemetry, std::vector<Bytes>& frames) {
    frames.clear();  // RAW_IMU alone, in ArduPilot's units (mG, mrad/s); the numbers the others took are gaps
    const mav::ScaledImu2 v = scaled_imu2(s);
    frames.push_back(telemetry.frame(mav::RawImu{.time_usec = us(s.time_s),
                                                 .xacc = v.xacc,
                                                 .yacc = v.yacc,
                                                 .zacc = v.zacc,
                                                 .xgyro = v.xgyro,
                                                 .ygyro = v.ygyro,
                                                 .zgyro = v.zgyro,
                                                 .zmag = 32767}));
  });
  store::Store store(dir_ / "import.db");
  try {
    import_tlog(store, {.file = write(f.tlog)});
    ADD_FAILURE() << "imported RAW_IMU without resolutions";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("give their resolution with --accel-lsb and --gyro-lsb"), std::string::npos)
        << e.what();
  }
  EXPECT_TRUE(store.sessions().empty());
  EXPECT_THROW(import_tlog(store, {.file = write(f.tlog), .accel_lsb = 9.80665e-3}), std::invalid_argument);
  ReportedProblems problems;
  const auto r = import_tlog(
      store, {.file = write(f.tlog), .accel_lsb = 9.80665e-3, .gyro_lsb = 1e-3, .on_problem = problems.callback()});
  EXPECT_EQ(r.imu_source, "RAW_IMU id 0 from system 1, component 1");
  const auto s = stored_samples(store, r.session);
  ASSERT_EQ(s.size(), f.samples.size());
  EXPECT_NEAR(s[5].accel[2], f.samples[5].measured.accel.z(), 0.5e-3 * 9.80665 + 1e-9);
  EXPECT_NEAR(s[5].gyro[0], f.samples[5].measured.gyro.x(), 0.5e-3 + 1e-9);
  EXPECT_TRUE(problems.of(ProblemKind::clipped).empty());  // the magnetometer's range is no concern
  EXPECT_TRUE(r.reference_source.empty());
  EXPECT_EQ(r.reference_rows, 0u);
}

TEST_F(TlogImport, ATruncatedLogImportsWhatPrecedesTheDamageAndSaysSo) {
  const Flight f = fly(1.0);
  const tlog::Log whole = tlog::parse(f.tlog);
  const std::size_t cut = whole.records[150].offset + 20;  // inside record 150
  store::Store store(dir_ / "import.db");
  ReportedProblems problems;
  const auto r = import_tlog(store, {.file = write(Bytes(f.tlog.begin(), f.tlog.begin() + static_cast<long>(cut))),
                                     .on_problem = problems.callback()});
  EXPECT_EQ(r.records, 150u);
  std::uint64_t imu_records = 0;  // HIGHRES_IMU among the 150 records kept
  for (std::size_t i = 0; i < 150; ++i) imu_records += whole.frame(whole.records[i])[7] == mav::HighresImu::kId;
  EXPECT_GT(imu_records, 100u);
  EXPECT_EQ(r.samples, imu_records);
  EXPECT_EQ(stored_samples(store, r.session).size(), imu_records);  // every good record before the damage
  const auto damage = problems.of(ProblemKind::damaged);
  ASSERT_EQ(damage.size(), 1u);
  EXPECT_EQ(damage[0].count, 20u);
  EXPECT_TRUE(damage[0].what.starts_with("bytes of ")) << damage[0].what;
  EXPECT_TRUE(damage[0].why.starts_with("the last record, cut short (20 bytes")) << damage[0].why;
  EXPECT_EQ(damage[0].where, "at byte " + std::to_string(whole.records[150].offset) + ", after record 150");
  const auto damaged = stored_events(store, r.session, "import_damaged");
  ASSERT_EQ(damaged.size(), 1u);
  EXPECT_EQ(damaged[0].count, 20);
  EXPECT_NE(damaged[0].detail.find("at byte " + std::to_string(whole.records[150].offset)), std::string::npos);
}

TEST_F(TlogImport, GarbageIsAOneLineErrorAndWritesNothing) {
  std::mt19937 rng(9);
  Bytes garbage(5000);
  for (auto& b : garbage) b = static_cast<std::uint8_t>(rng());
  store::Store store(dir_ / "import.db");
  const fs::path path = write(garbage, "garbage.tlog");
  try {
    import_tlog(store, {.file = path});
    ADD_FAILURE() << "garbage imported";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()), path.string() +
                                         ": not a MAVLink telemetry log (tlog): no record (an 8-byte time, then a "
                                         "MAVLink frame) in its first 1024 bytes");
  }
  EXPECT_THROW(import_tlog(store, {.file = dir_ / "absent.tlog"}), std::invalid_argument);
  EXPECT_TRUE(store.sessions().empty());
}

// A log whose time stops for 3 s and steps back, with STATUSTEXT from a companion computer: events for each, and the
// session's clock never goes back.
TEST_F(TlogImport, GapsStepsBackAndStatusTextAreEvents) {
  const Flight f = fly(1.0);
  const tlog::Log log = tlog::parse(f.tlog);
  Bytes bytes;
  std::uint8_t companion_seq = 0;
  for (std::size_t i = 0; i < log.records.size(); ++i) {
    std::uint64_t t = log.records[i].time_us;
    if (i >= 100) t += 3'000'000;
    if (i >= 200) t -= 3'500'000;  // 0.5 s before the record before it
    tlog::append_record(bytes, t, log.frame(log.records[i]));
    if (i == 50) {
      Bytes payload(51, 0);
      payload[0] = 4;  // MAV_SEVERITY_WARNING
      const std::string text = "Battery 1 low";
      std::copy(text.begin(), text.end(), payload.begin() + 1);
      Bytes frame;
      mav::encode(mav::make_message(253, payload, {.seq = companion_seq++, .sysid = 1, .compid = 191}), frame);
      tlog::append_record(bytes, t, frame);
    }
  }
  store::Store store(dir_ / "import.db");
  const auto r = import_tlog(store, {.file = write(bytes)});
  EXPECT_EQ(r.log_gaps, 1u);
  EXPECT_NEAR(r.log_gap_s, 3 + static_cast<double>(log.records[100].time_us - log.records[99].time_us) * 1e-6, 1e-9);
  EXPECT_EQ(r.time_back, 1u);
  EXPECT_EQ(r.log_events, 1u);
  const auto log_events = stored_events(store, r.session, "log");
  ASSERT_EQ(log_events.size(), 1u);
  EXPECT_EQ(log_events[0].detail, "warning: Battery 1 low");
  const auto gap = stored_events(store, r.session, "log_gap");
  ASSERT_EQ(gap.size(), 1u);
  EXPECT_EQ(gap[0].detail, "no record in the log for 3.0 s");
  // The IMU's samples stop for the same 3 s: a hole in the data, with its span in session time.
  ASSERT_EQ(r.gaps.holes.size(), 1u);
  EXPECT_NEAR(r.gaps.holes[0].seconds(), 3, 0.05);
  const auto hole = stored_events(store, r.session, "gap");
  ASSERT_EQ(hole.size(), 1u);
  EXPECT_EQ(hole[0].mono_ns, r.gaps.holes[0].from_ns);
  EXPECT_TRUE(hole[0].detail.starts_with("no IMU sample for 3.0")) << hole[0].detail;
  ASSERT_EQ(stored_events(store, r.session, "log_time_back").size(), 1u);
  const auto s = stored_samples(store, r.session);
  for (std::size_t i = 1; i < s.size(); ++i) ASSERT_GE(s[i].recv_mono_ns, s[i - 1].recv_mono_ns) << i;
}

TEST_F(TlogImport, NoReferenceWhenAskedAndAxesAsDeclared) {
  const Flight f = fly(1.0);
  store::Store store(dir_ / "import.db");
  const auto r = import_tlog(store, {.file = write(f.tlog), .imu_axes = "flu", .reference = false});
  EXPECT_EQ(r.reference_rows, 0u);
  EXPECT_TRUE(stored_reference(store, r.session).empty());
  EXPECT_TRUE(r.axes.mismatch);  // gravity on -z: FRD, not FLU
}

}  // namespace
}  // namespace imubridge::importers
