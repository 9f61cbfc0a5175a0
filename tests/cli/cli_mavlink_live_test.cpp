// `imubridge run` on a live MAVLink link: a simulated flight controller writes MAVLink into a pseudo-terminal with
// two IMUs (SCALED_IMU2 and HIGHRES_IMU, different values), ATTITUDE and LOCAL_POSITION_NED; the daemon must keep
// to one IMU, record it so replay decodes the same samples, and write nothing to the port.
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <fstream>
#include <set>

#include "pipeline/session_config.hpp"
#include "protocol/mavlink.hpp"
#include "protocol/mavlink_messages.hpp"
#include "sim/frame_encoder.hpp"
#include "tests/support/cli_run_harness.hpp"

namespace imubridge::test {
namespace {

namespace mav = protocol::mavlink;

// The vehicle's frames, whole, in the order it sends them: a SCALED_IMU2 before every other sample's HIGHRES_IMU
// (so the first IMU heard is SCALED_IMU2), and the simulator's telemetry (HIGHRES_IMU of every sample, ATTITUDE and
// LOCAL_POSITION_NED of every tenth). All from system 1, component 1.
struct Vehicle {
  std::vector<std::vector<std::uint8_t>> frames;
  std::vector<sim::TrueState> truth;  // at each LOCAL_POSITION_NED, in order
};
Vehicle vehicle_frames(std::size_t count) {
  const auto samples = sim::simulate(sim::make_scenario("paper", 5, static_cast<double>(count) / 200.0 + 0.1));
  sim::MavlinkTelemetry telemetry;
  Vehicle v;
  for (std::size_t i = 0; i < count && i < samples.size(); ++i) {
    if (i % 2 == 0) {
      const auto ms = static_cast<std::uint32_t>(samples[i].time_s * 1000);
      v.frames.push_back(
          telemetry.frame(mav::ScaledImu2{.time_boot_ms = ms, .xacc = 100, .yacc = -50, .zacc = -1000, .xgyro = 7}));
    }
    const std::size_t before = v.frames.size();
    telemetry.encode(samples[i], v.frames);
    if (v.frames.size() > before + 1) v.truth.push_back(samples[i].truth);
  }
  return v;
}

// What a decoder of the frames finds: each message, in order.
std::vector<mav::Message> messages_of(const std::vector<std::vector<std::uint8_t>>& frames) {
  mav::Decoder decoder;
  std::vector<mav::Message> out;
  for (const auto& f : frames) decoder.feed(f, out);
  return out;
}

// The samples of one IMU message among the frames.
std::vector<protocol::Sample> samples_of(const std::vector<std::vector<std::uint8_t>>& frames, std::uint32_t msgid) {
  std::vector<protocol::Sample> out;
  for (const mav::Message& m : messages_of(frames)) {
    if (m.msgid != msgid) continue;
    if (auto s = mav::to_sample(m, nullptr)) out.push_back(*s);
  }
  return out;
}

class MavlinkLiveTest : public ::testing::Test {
 protected:
  void write_config(const std::string& link_keys) {
    std::ofstream(config_) << "stats_interval_s = 3600\n[store]\npath = \"" << db_.string()
                           << "\"\nmin_free_mib = 0\n[[link]]\nname = \"fc\"\ndevice = \"" << tty_.string()
                           << "\"\nprotocol = \"mavlink\"\naxes = \"frd\"\nreconnect_min_ms = 10\n"
                           << "reconnect_max_ms = 50\n"
                           << link_keys;
  }
  // Runs the daemon over the vehicle's frames and stops it; returns what it wrote to the port.
  std::vector<std::uint8_t> record(const std::vector<std::vector<std::uint8_t>>& frames, std::size_t samples) {
    cli::PtyPair pty(tty_);
    Process daemon({"run", "--config", config_.string()}, dir_ / "stderr");
    EXPECT_TRUE(daemon.wait_for_log("link 'fc': reading")) << daemon.log();
    // Each LOCAL_POSITION_NED is read before what follows it is written: a chunk carries at most one (two in one
    // chunk would share its receive time, and the second row would be skipped as not after the first).
    std::vector<std::vector<std::uint8_t>> burst;
    for (const auto& frame : frames) {
      burst.push_back(frame);
      if (frame.size() > 9 && frame[7] == 32 && frame[8] == 0 && frame[9] == 0) {  // MAVLink 2 id 32
        write_paced(pty, burst);
        EXPECT_EQ(pty.drain(std::chrono::seconds(20)), 0u);
        burst.clear();
      }
    }
    write_paced(pty, burst);
    EXPECT_TRUE(wait_for_samples(db_, samples)) << daemon.log();
    daemon.signal(SIGTERM);
    EXPECT_EQ(daemon.wait(), 0) << daemon.log();
    log_ = daemon.log();
    std::vector<std::uint8_t> written;
    std::uint8_t buffer[4096];
    for (ssize_t n; (n = ::read(pty.master_fd(), buffer, sizeof buffer)) > 0;)
      written.insert(written.end(), buffer, buffer + n);
    return written;
  }

  TempDir dir_;
  fs::path config_ = dir_ / "imubridge.toml", db_ = dir_ / "run.db", tty_ = dir_ / "tty";
  std::string log_;
};

void expect_same_accel(const std::vector<protocol::Sample>& got, const std::vector<protocol::Sample>& want) {
  ASSERT_EQ(got.size(), want.size());
  for (std::size_t i = 0; i < got.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      ASSERT_EQ(got[i].accel[k], want[i].accel[k]) << i;
      ASSERT_EQ(got[i].gyro[k], want[i].gyro[k]) << i;
    }
  }
}

// A replay of the session estimates from the samples the live run estimated from: same samples, same estimates.
void expect_replay_reproduces(const fs::path& db) {
  const auto replay = run_imubridge("replay --db " + db.string() + " --session 1");
  ASSERT_EQ(replay.exit_code, 0) << replay.err;
  const store::Store store(db, {.read_only = true});
  const auto runs = store.runs(1);
  ASSERT_EQ(runs.size(), 2u);
  std::vector<std::array<double, 4>> live, replayed;
  store.for_each_estimate(runs[0].id, [&](const store::Estimate& e) {
    live.push_back({double(e.seq), e.fx, e.fy, e.t_s});
  });
  store.for_each_estimate(runs[1].id, [&](const store::Estimate& e) {
    replayed.push_back({double(e.seq), e.fx, e.fy, e.t_s});
  });
  EXPECT_FALSE(live.empty());
  EXPECT_EQ(replayed, live);
}

// The reference rows: one per LOCAL_POSITION_NED, the truth the vehicle sent (float precision), each stamped with
// the receive time of a chunk, the clock the samples carry.
void expect_reference_is_truth(const store::Store& store, const std::vector<sim::TrueState>& truth) {
  std::vector<store::ReferenceRow> rows;
  store.for_each_reference(1, [&](const store::ReferenceRow& r) { rows.push_back(r); });
  std::set<std::int64_t> chunk_times;
  store.for_each_chunk(1, std::nullopt, [&](const store::Chunk& c) { chunk_times.insert(c.recv_mono_ns); });
  ASSERT_EQ(rows.size(), truth.size());
  for (std::size_t i = 0; i < rows.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(rows[i].position[k], truth[i].position_ned[k], 1e-4 * (1 + std::abs(truth[i].position_ned[k]))) << i;
      ASSERT_TRUE(rows[i].velocity.has_value());
      EXPECT_NEAR((*rows[i].velocity)[k], truth[i].velocity_ned[k], 1e-4 * (1 + std::abs(truth[i].velocity_ned[k])));
    }
    const Eigen::Quaterniond q(rows[i].quat_wxyz[0], rows[i].quat_wxyz[1], rows[i].quat_wxyz[2], rows[i].quat_wxyz[3]);
    EXPECT_GT(std::abs(q.dot(truth[i].attitude)), 1 - 1e-6) << i;
    EXPECT_TRUE(chunk_times.contains(rows[i].t_ns)) << i;
    if (i > 0) {
      EXPECT_GT(rows[i].t_ns, rows[i - 1].t_ns);
    }
  }
}

// Without `imu` the link keeps to the first IMU it hears (SCALED_IMU2 here), says so in the log and the session,
// and the HIGHRES_IMU messages give no samples. Nothing is written to the vehicle.
TEST_F(MavlinkLiveTest, ALinkLocksOnTheFirstImuItHears) {
  const Vehicle vehicle = vehicle_frames(400);
  const auto& frames = vehicle.frames;
  const auto want = samples_of(frames, mav::ScaledImu2::kId);
  write_config("");
  const auto written = record(frames, want.size());
  EXPECT_TRUE(written.empty()) << written.size() << " bytes written to the port";
  EXPECT_EQ(count_of(log_, "samples from SCALED_IMU2 from system 1, component 1 only"), 1) << log_;

  const store::Store store(db_, {.read_only = true});
  std::vector<protocol::Sample> got;
  store.for_each_sample(1, std::nullopt, [&](const protocol::Sample& s) { got.push_back(s); });
  expect_same_accel(got, want);
  const auto events = store.events(1);
  EXPECT_EQ(std::count_if(events.begin(), events.end(),
                          [](const store::Event& e) {
                            return e.kind == "mavlink_imu" &&
                                   e.detail.find("SCALED_IMU2 from system 1, component 1") != std::string::npos;
                          }),
            1);
  expect_replay_reproduces(db_);
  expect_reference_is_truth(store, vehicle.truth);
}

// The autopilot's land detector (EXTENDED_SYS_STATE every 40 frames: on the ground for the first half, then in the
// air): the daemon logs the take-off, stores it as an event, and while landed the velocity is measured rest even with
// nothing identified (after it: NaN, no drag to read); a replay gives the same velocities from the same bytes.
TEST_F(MavlinkLiveTest, TheAutopilotsLandDetectorIsLoggedStoredAndHoldsTheVelocityAtRest) {
  const Vehicle vehicle = vehicle_frames(400);
  sim::MavlinkTelemetry autopilot;
  std::vector<std::vector<std::uint8_t>> frames;
  for (std::size_t i = 0; i < vehicle.frames.size(); ++i) {
    frames.push_back(vehicle.frames[i]);
    if (i % 40 == 20) {
      const auto state = i < vehicle.frames.size() / 2 ? mav::LandedState::on_ground : mav::LandedState::in_air;
      frames.push_back(autopilot.frame(mav::ExtendedSysState{.landed_state = static_cast<std::uint8_t>(state)}));
    }
  }
  write_config("");
  record(frames, samples_of(frames, mav::ScaledImu2::kId).size());
  EXPECT_EQ(count_of(log_, "link 'fc': the autopilot (system 1) says no longer landed"), 1) << log_;
  EXPECT_EQ(count_of(log_, "says landed"), 0) << log_;

  const store::Store store(db_, {.read_only = true});
  const auto events = store.events(1);
  EXPECT_EQ(std::count_if(events.begin(), events.end(), [](const store::Event& e) { return e.kind == "takeoff"; }), 1);
  EXPECT_EQ(std::count_if(events.begin(), events.end(), [](const store::Event& e) { return e.kind == "landing"; }), 0);
  const auto velocities = [&](std::int64_t run) {
    std::vector<std::array<double, 3>> out;
    store.for_each_estimate(run, [&](const store::Estimate& e) { out.push_back({e.t_s, e.vx, e.var_vx}); });
    return out;
  };
  const auto live = velocities(store.runs(1).at(0).id);
  std::size_t at_rest = 0;
  for (const auto& [t, vx, var] : live) at_rest += std::abs(vx) < 0.05 && var < 0.05 * 0.05;
  EXPECT_GT(at_rest, 50u);
  ASSERT_FALSE(live.empty());
  EXPECT_TRUE(std::isnan(live.back()[1]));  // in the air, with no drag identified: unknown
  const auto replay = run_imubridge("replay --db " + db_.string() + " --session 1");
  ASSERT_EQ(replay.exit_code, 0) << replay.err;
  const store::Store replayed_store(db_, {.read_only = true});
  const auto runs = replayed_store.runs(1);
  ASSERT_EQ(runs.size(), 2u);
  std::vector<std::array<double, 3>> replayed;
  replayed_store.for_each_estimate(runs[1].id, [&](const store::Estimate& e) {
    replayed.push_back({e.t_s, e.vx, e.var_vx});
  });
  ASSERT_EQ(replayed.size(), live.size());
  for (std::size_t i = 0; i < live.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      ASSERT_TRUE(live[i][k] == replayed[i][k] || (std::isnan(live[i][k]) && std::isnan(replayed[i][k]))) << i;
    }
  }
}

// `imu = "HIGHRES_IMU"`: only its samples, although SCALED_IMU2 came first.
TEST_F(MavlinkLiveTest, TheConfiguredImuIsTheOneRecorded) {
  const Vehicle vehicle = vehicle_frames(400);
  const auto& frames = vehicle.frames;
  const auto want = samples_of(frames, mav::HighresImu::kId);
  ASSERT_EQ(want.size(), 400u);
  write_config("imu = \"HIGHRES_IMU\"\n");
  record(frames, want.size());
  EXPECT_NE(log_.find("samples from HIGHRES_IMU id 0 from system 1, component 1 only"), std::string::npos) << log_;
  const store::Store store(db_, {.read_only = true});
  std::vector<protocol::Sample> got;
  store.for_each_sample(1, std::nullopt, [&](const protocol::Sample& s) { got.push_back(s); });
  expect_same_accel(got, want);
  expect_replay_reproduces(db_);
  expect_reference_is_truth(store, vehicle.truth);
}

// `request_rates`: at the port's opening, before the vehicle is heard, one COMMAND_LONG MAV_CMD_SET_MESSAGE_INTERVAL
// per entry, broadcast (target 0, 0), from system 255 component 190; and they are recorded as the link's tx chunks.
TEST_F(MavlinkLiveTest, StreamRequestsAreSentAtOpening) {
  const Vehicle vehicle = vehicle_frames(100);
  write_config(
      "imu = \"HIGHRES_IMU\"\nrequest_rates = { HIGHRES_IMU = 200, LOCAL_POSITION_NED = 50, ATTITUDE = 12.5 }\n");
  const auto written = record(vehicle.frames, 100);
  std::vector<mav::Message> commands;
  mav::Decoder decoder;
  decoder.feed(written, commands);
  ASSERT_EQ(commands.size(), 3u) << written.size() << " bytes written";
  const auto param = [](const mav::Message& m, std::size_t at) {
    std::uint32_t bits = 0;
    for (int i = 0; i < 4; ++i) bits |= std::uint32_t{m.payload[at + i]} << (8 * i);
    return std::bit_cast<float>(bits);
  };
  // In the map's order: by name.
  const std::vector<std::pair<float, float>> want{{30, 80000}, {105, 5000}, {32, 20000}};
  for (std::size_t i = 0; i < commands.size(); ++i) {
    const mav::Message& m = commands[i];
    EXPECT_EQ(m.msgid, 76u);
    EXPECT_EQ(m.sysid, 255);
    EXPECT_EQ(m.compid, 190);
    EXPECT_EQ(param(m, 0), want[i].first) << i;
    EXPECT_EQ(param(m, 4), want[i].second) << i;
    EXPECT_EQ(m.payload[28] | m.payload[29] << 8, 511);
    EXPECT_EQ(m.payload[30], 0) << "broadcast: the vehicle was not heard yet";
    EXPECT_EQ(m.payload[31], 0);
  }
  EXPECT_EQ(decoder.counters().crc_failures, 0u);
  const store::Store store(db_, {.read_only = true});
  std::vector<std::uint8_t> tx;
  store.for_each_chunk(1, std::nullopt, [&](const store::Chunk& c) {
    if (c.direction == store::Direction::tx) tx.insert(tx.end(), c.bytes.begin(), c.bytes.end());
  });
  EXPECT_EQ(tx, written);
}

// At a reopening the requests go again, now to the vehicle heard before the port vanished (system 1, component 1).
TEST_F(MavlinkLiveTest, StreamRequestsGoAgainAtAReopeningToTheVehicleHeard) {
  const Vehicle vehicle = vehicle_frames(100);
  write_config("request_rates = { HIGHRES_IMU = 100 }\n");
  auto pty = std::make_unique<cli::PtyPair>(tty_);
  Process daemon({"run", "--config", config_.string()}, dir_ / "stderr");
  ASSERT_TRUE(daemon.wait_for_log("link 'fc': reading")) << daemon.log();
  write_paced(*pty, vehicle.frames);
  ASSERT_TRUE(wait_for_samples(db_, 1)) << daemon.log();
  ASSERT_TRUE(daemon.wait_for_log("samples from")) << daemon.log();
  pty.reset();
  ASSERT_TRUE(daemon.wait_for_log("lost /")) << daemon.log();
  pty = std::make_unique<cli::PtyPair>(tty_);
  ASSERT_TRUE(daemon.wait_for_log("asked system 1, component 1 for HIGHRES_IMU at 100 Hz")) << daemon.log();
  std::vector<std::uint8_t> written(4096);
  std::vector<mav::Message> commands;
  mav::Decoder decoder;
  ASSERT_TRUE(eventually([&] {
    const ssize_t n = ::read(pty->master_fd(), written.data(), written.size());
    if (n > 0) decoder.feed(std::span(written.data(), static_cast<std::size_t>(n)), commands);
    return !commands.empty();
  }));
  daemon.signal(SIGTERM);
  EXPECT_EQ(daemon.wait(), 0) << daemon.log();
  ASSERT_EQ(commands.size(), 1u);
  EXPECT_EQ(commands[0].msgid, 76u);
  EXPECT_EQ(commands[0].payload[30], 1) << "target system";
  EXPECT_EQ(commands[0].payload[31], 1) << "target component";
  EXPECT_EQ(commands[0].seq, 1) << "the ground station's second frame";
  EXPECT_EQ(count_of(daemon.log(), "asked every system (not heard yet) for HIGHRES_IMU at 100 Hz"), 1) << daemon.log();
}

// A rotation begins a new session after the link has locked: it keeps to the same IMU (recorded as "mavlink_imu"),
// whichever IMU's message comes first in the new file.
TEST_F(MavlinkLiveTest, ARotationKeepsTheImuTheLinkLockedOn) {
  const Vehicle vehicle = vehicle_frames(16000);
  const auto scaled = samples_of(vehicle.frames, mav::ScaledImu2::kId);
  std::ofstream(config_) << "stats_interval_s = 3600\n[store]\npath = \"" << db_.string()
                         << "\"\nmin_free_mib = 0\nmax_size_mib = 1\ncommit_interval_ms = 50\n[[link]]\nname = \"fc\"\n"
                         << "device = \"" << tty_.string() << "\"\nprotocol = \"mavlink\"\naxes = \"frd\"\n";
  cli::PtyPair pty(tty_);
  Process daemon({"run", "--config", config_.string()}, dir_ / "stderr");
  ASSERT_TRUE(daemon.wait_for_log("link 'fc': reading")) << daemon.log();
  write_paced(pty, vehicle.frames);
  EXPECT_EQ(pty.drain(std::chrono::seconds(20)), 0u);
  daemon.signal(SIGTERM);
  ASSERT_EQ(daemon.wait(), 0) << daemon.log();
  ASSERT_GE(count_of(daemon.log(), "reached store.max_size_mib"), 1) << daemon.log();
  int files = 0;
  std::size_t samples = 0;
  for (const auto& entry : fs::directory_iterator(dir_.path())) {
    if (entry.path().extension() != ".db") continue;
    ++files;
    const store::Store store(entry.path(), {.read_only = true});
    for (const auto& session : store.sessions()) {
      std::size_t others = 0;
      store.for_each_sample(session.id, std::nullopt, [&](const protocol::Sample& s) {
        ++samples;
        others += s.accel != scaled[0].accel;
      });
      EXPECT_EQ(others, 0u) << entry.path() << ": HIGHRES_IMU samples";
      const auto links = pipeline::recorded_links(session.info.config);
      ASSERT_EQ(links.size(), 1u);
      EXPECT_TRUE(links[0].mavlink_imu || links[0].mavlink_imu_lock) << entry.path();
    }
  }
  EXPECT_GE(files, 2);
  EXPECT_GE(samples + files, scaled.size()) << "a frame cut by a rotation is lost, no more";
}

}  // namespace
}  // namespace imubridge::test
