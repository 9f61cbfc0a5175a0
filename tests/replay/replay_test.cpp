// Replay against a live run recorded as the daemon records one, for every wire format: the same chunks and
// parameters must give the same estimates bit for bit. Also: windows, XBee radios, what cannot be replayed, pacing.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <random>

#include "pipeline/estimation_stage.hpp"
#include "pipeline/link_recorder.hpp"
#include "pipeline/session_config.hpp"
#include "protocol/imu_frame.hpp"
#include "protocol/xbee.hpp"
#include "replay/replayer.hpp"
#include "replay/session_lookup.hpp"
#include "sim/frame_encoder.hpp"
#include "sim/scenario.hpp"
#include "tests/support/paper_params.hpp"

namespace imubridge::replay {
namespace {

namespace fs = std::filesystem;
using protocol::WireFormat;

constexpr std::int64_t kMonoAtStart = 7'000'000'000;              // the ground station's uptime when recording began
constexpr std::int64_t kWallAtStart = 1'700'000'000'000'000'000;  // and the wall clock then

using test::paper_params;

// A received byte stream: chunks with their receive times, in seconds since recording began.
using Stream = std::vector<std::pair<double, std::vector<std::uint8_t>>>;

// A simulated flight's bytes: as a serial driver hands them over (cut at random points, with line noise and bit
// flips), or clean, one chunk per sample.
Stream serial_stream(WireFormat format, double seconds, bool realistic) {
  sim::FrameEncoder encoder(format);
  std::mt19937 rng(3);
  Stream stream;
  std::vector<std::uint8_t> bytes;
  for (const auto& s : sim::simulate(sim::make_scenario("paper", 9, seconds))) {
    bytes.clear();
    encoder.encode(s, bytes);
    if (realistic && s.index % 97 == 50) bytes.insert(bytes.begin(), {0xB7, 0x4D, 0x7E, 0x00});  // false starts
    if (realistic && s.index % 131 == 70 && !bytes.empty()) bytes[bytes.size() / 2] ^= 0x04;     // a bit flip
    std::span<const std::uint8_t> rest(bytes);
    while (!rest.empty()) {
      const std::size_t n = realistic ? std::min<std::size_t>(rest.size(), 1 + rng() % 40) : rest.size();
      stream.emplace_back(s.time_s, std::vector<std::uint8_t>(rest.begin(), rest.begin() + n));
      rest = rest.subspan(n);
    }
  }
  return stream;
}

bool same(double a, double b) { return a == b || (std::isnan(a) && std::isnan(b)); }

std::map<std::int64_t, std::vector<store::Estimate>> estimates_by_link(const store::Store& store, std::int64_t run) {
  std::map<std::int64_t, std::vector<store::Estimate>> out;
  store.for_each_estimate(run, [&](const store::Estimate& e) { out[e.link_id].push_back(e); });
  return out;
}

// Exact comparison of two runs' stored estimates, link by link (NaN equals NaN).
void expect_identical_runs(const store::Store& store, std::int64_t a, std::int64_t b) {
  const auto ea = estimates_by_link(store, a), eb = estimates_by_link(store, b);
  ASSERT_EQ(ea.size(), eb.size());
  for (const auto& [link, list] : ea) {
    ASSERT_TRUE(eb.contains(link)) << "link " << link;
    const auto& other = eb.at(link);
    ASSERT_EQ(list.size(), other.size()) << "link " << link;
    for (std::size_t i = 0; i < list.size(); ++i) {
      const auto &x = list[i], &y = other[i];
      EXPECT_TRUE(x.seq == y.seq && same(x.t_s, y.t_s) && same(x.fx, y.fx) && same(x.fy, y.fy) && same(x.vx, y.vx) &&
                  same(x.vy, y.vy) && same(x.var_vx, y.var_vx) && same(x.var_vy, y.var_vy))
          << "link " << link << ", estimate " << i << " (seq " << x.seq << " vs " << y.seq << ")";
    }
  }
}

class Replay : public ::testing::Test {
 protected:
  fs::path path_ = fs::temp_directory_path() / ("imubridge_replay_" + std::to_string(::getpid()) + ".db");
  void TearDown() override {
    for (const char* suffix : {"", "-wal", "-shm"}) fs::remove(path_.string() + suffix);
  }

  struct Recorded {
    std::int64_t session = 0;
    std::optional<std::int64_t> live_run;
  };

  // Records `stream` on link "imu0" as the daemon does: each read through the session engine, whose recording stores
  // it and, with params, the EstimationStage's estimates into a run of kind "live" whose params are those it used.
  Recorded record(store::Store& store, WireFormat format, const Stream& stream,
                  std::optional<estimator::ModelParams> params) {
    const std::vector<pipeline::SessionLink> links{
        {.recorded = {"imu0", format, protocol::Calibration::reference_board()}, .device = "test port"}};
    const pipeline::RecordedSession begun =
        pipeline::begin_recorded_session(store,
                                         {.kind = "live",
                                          .source = "test",
                                          .config = {{"note", "recorded by replay_test"}},
                                          .started_wall_ns = kWallAtStart,
                                          .estimated_with = params},
                                         links);
    pipeline::SessionEngine engine(params ? std::make_unique<pipeline::EstimationStage>(*params) : nullptr);
    engine.add_link(pipeline::make_decoder(links[0].recorded));
    pipeline::SessionRecording recording(store, begun, links, engine);
    engine.add_sink(recording);
    std::int64_t mono = kMonoAtStart;
    for (const auto& [t, bytes] : stream) {
      mono = std::max<std::int64_t>(mono + 1, kMonoAtStart + std::llround(t * 1e9));  // every read a little later
      engine.on_chunk(0, bytes, mono, kWallAtStart + (mono - kMonoAtStart));
    }
    engine.finish_link(0, mono, kWallAtStart + (mono - kMonoAtStart));
    engine.finish();
    pipeline::end_recorded_session(store, begun.id, kWallAtStart + (mono - kMonoAtStart));
    return {.session = begun.id, .live_run = begun.run};
  }
};

class ReplayEveryFormat : public Replay, public ::testing::WithParamInterface<WireFormat> {};

TEST_P(ReplayEveryFormat, WithTheLiveRunsParamsReproducesItBitForBit) {
  store::Store store(path_);
  const auto rec = record(store, GetParam(), serial_stream(GetParam(), 4.0, true), paper_params());
  const auto result = replay_session(store, rec.session);
  EXPECT_GT(result.estimates, 700u);  // 800 samples at 200 Hz, a few lost to the bit flips
  expect_identical_runs(store, *rec.live_run, result.run);

  const auto runs = store.runs(rec.session);
  ASSERT_EQ(runs.size(), 2u);
  EXPECT_EQ(runs[1].info.kind, "replay");
  EXPECT_EQ(estimator::parse_params(runs[1].info.params_json, "the replay"), paper_params());
}

INSTANTIATE_TEST_SUITE_P(Replay, ReplayEveryFormat,
                         ::testing::Values(WireFormat::imubridge, WireFormat::xbee, WireFormat::xbee_escaped,
                                           WireFormat::mavlink),
                         [](const auto& info) {
                           std::string name(protocol::wire_format_name(info.param));
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name;
                         });

TEST_F(Replay, TwoReplaysAreIdenticalAndUseTheDefaultsWithoutALiveRun) {
  store::Store store(path_);
  const auto rec = record(store, WireFormat::imubridge, serial_stream(WireFormat::imubridge, 2.0, true), {});
  const auto first = replay_session(store, rec.session);
  const auto second = replay_session(store, rec.session);
  EXPECT_EQ(first.estimates, second.estimates);
  expect_identical_runs(store, first.run, second.run);
  // Default parameters identify nothing: compensation only, velocity NaN (stored as NULL, read back as NaN).
  const auto estimates = estimates_by_link(store, first.run);
  ASSERT_FALSE(estimates.empty());
  EXPECT_TRUE(std::isnan(estimates.begin()->second.front().vx));
  EXPECT_EQ(estimator::parse_params(store.runs(rec.session).front().info.params_json, "run"), estimator::ModelParams{});
}

TEST_F(Replay, GivenParamsOverrideTheLiveRunsAndAreRecorded) {
  store::Store store(path_);
  const auto rec =
      record(store, WireFormat::imubridge, serial_stream(WireFormat::imubridge, 2.0, false), paper_params());
  estimator::ModelParams other = paper_params();
  other.full.drag_quadratic = {0.2, 0.2};
  const auto result = replay_session(store, rec.session, {.params = other});
  EXPECT_EQ(estimator::parse_params(store.runs(rec.session).back().info.params_json, "the replay"), other);
  const auto live = estimates_by_link(store, *rec.live_run).begin()->second;
  const auto replayed = estimates_by_link(store, result.run).begin()->second;
  ASSERT_EQ(live.size(), replayed.size());
  std::size_t different = 0;
  for (std::size_t i = 0; i < live.size(); ++i) different += live[i].vx != replayed[i].vx;
  EXPECT_GT(different, live.size() / 2);
}

// An imported log's land detector (import ulog stores PX4's as the session's takeoff and landing events): replay fuses
// rest while it says landed, and the drag law between; the same session without the events reads the drag throughout.
// A MAVLink link's detector is in its bytes: stored events never override them, so its replay stays its live run's.
TEST_F(Replay, AStoredLandDetectorHoldsTheVelocityAtRestOnTheGroundExceptWhereTheBytesCarryTheirOwn) {
  store::Store store(path_);
  const Stream stream = serial_stream(WireFormat::imubridge, 4.0, false);
  const auto plain = record(store, WireFormat::imubridge, stream, {});
  const auto detected = record(store, WireFormat::imubridge, stream, {});
  const auto event = [&](std::int64_t session, double t, const char* kind) {
    const std::int64_t mono = kMonoAtStart + std::llround(t * 1e9);
    store.append_event(session, {.mono_ns = mono, .wall_ns = kWallAtStart + mono - kMonoAtStart, .kind = kind});
  };
  event(detected.session, 3.0, "landing");  // stored out of order: replay sorts them
  event(detected.session, 1.5, "takeoff");
  const auto without = estimates_by_link(store, replay_session(store, plain.session, {.params = paper_params()}).run);
  const auto with = estimates_by_link(store, replay_session(store, detected.session, {.params = paper_params()}).run);
  ASSERT_EQ(without.size(), 1u);
  ASSERT_EQ(with.size(), 1u);
  const auto& a = without.begin()->second;
  const auto& b = with.begin()->second;
  ASSERT_EQ(a.size(), b.size());
  double ground_speed_without = 0.0, air_speed = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].t_s, b[i].t_s);
    const double t = b[i].t_s;
    if (t < 1.45 || t > 3.1) {  // landed: before the takeoff (the first event) and after the landing
      ASSERT_LT(std::hypot(b[i].vx, b[i].vy), 0.05) << t;
      ASSERT_LT(b[i].var_vx, 0.05 * 0.05) << t;
      ground_speed_without = std::max(ground_speed_without, std::hypot(a[i].vx, a[i].vy));
    } else if (t > 1.6 && t < 2.9) {
      air_speed = std::max(air_speed, std::hypot(b[i].vx, b[i].vy));
      EXPECT_GT(b[i].var_vx, 0.05 * 0.05) << t;  // the drag law's uncertainty again
    }
  }
  EXPECT_GT(ground_speed_without, 0.2);  // the simulated vehicle moves: without the events, the drag reads it
  EXPECT_GT(air_speed, 0.05);  // in the air it reads the drag again (from rest): no longer held within 0.05 m/s
  std::printf("largest speed on the ground without the events %.2f m/s; in the air with them %.2f m/s\n",
              ground_speed_without, air_speed);

  const auto mavlink =
      record(store, WireFormat::mavlink, serial_stream(WireFormat::mavlink, 2.0, false), paper_params());
  event(mavlink.session, 1.0, "takeoff");
  expect_identical_runs(store, *mavlink.live_run, replay_session(store, mavlink.session).run);
}

TEST_F(Replay, WindowReplaysTheChunksReceivedInItFromTheSessionsStart) {
  store::Store store(path_);
  // One frame per chunk: the window holds whole frames, so its samples are known exactly.
  const auto rec = record(store, WireFormat::imubridge, serial_stream(WireFormat::imubridge, 3.0, false), {});
  std::vector<protocol::Sample> in_window;
  store.for_each_sample(rec.session, std::nullopt, [&](const protocol::Sample& s) {
    const std::int64_t since_start = s.recv_mono_ns - kMonoAtStart;  // the session began at kMonoAtStart
    if (since_start >= 1'000'000'000 && since_start < 2'000'000'000) in_window.push_back(s);
  });
  ASSERT_GT(in_window.size(), 190u);
  const auto result = replay_session(store, rec.session, {.play = {.from_s = 1.0, .to_s = 2.0}});
  EXPECT_EQ(result.samples, in_window.size());
  EXPECT_DOUBLE_EQ(result.first_s, 1.0);
  EXPECT_LT(result.last_s, 2.0);
  // The estimator starts fresh at --from: its delay's worth of samples at each end of the window gets no estimate.
  const auto estimates = estimates_by_link(store, result.run).begin()->second;
  const std::size_t delay = 2;  // EstimationStage with the default configuration
  ASSERT_EQ(estimates.size(), in_window.size() - 2 * delay);
  for (std::size_t i = 0; i < estimates.size(); ++i) EXPECT_EQ(estimates[i].seq, in_window[i + delay].seq);

  EXPECT_THROW(replay_session(store, rec.session, {.play = {.from_s = 10.0}}), std::invalid_argument);
  EXPECT_THROW(replay_session(store, rec.session, {.play = {.from_s = 2.0, .to_s = 1.0}}), std::invalid_argument);
  EXPECT_EQ(store.runs(rec.session).size(), 1u);  // refused windows leave no run behind
}

// Two vehicles on one ground radio: each radio's samples carry its own store link, live and replayed.
TEST_F(Replay, XbeeRadiosMapToTheLinksRecordedForThem) {
  constexpr std::uint64_t kRadioA = 0x0013A20040000001, kRadioB = 0x0013A200400000B2;
  Stream stream;
  const auto a = sim::simulate(sim::make_scenario("paper", 1, 2.0));
  const auto b = sim::simulate(sim::make_scenario("hover", 2, 2.0));
  for (std::size_t i = 0; i < a.size(); ++i) {
    auto& [t, bytes] = stream.emplace_back(a[i].time_s, std::vector<std::uint8_t>{});
    for (const auto& [radio, s] : {std::pair{kRadioA, a[i]}, std::pair{kRadioB, b[i]}}) {
      protocol::xbee::RxPacket rx{.source64 = radio, .source16 = 0xFFFE, .options = 0x01, .payload = {}};
      protocol::imu::encode({.seq = static_cast<std::uint16_t>(i), .device_time_us = 5000 * i, .payload = s.raw},
                            rx.payload);
      protocol::xbee::encode({protocol::xbee::kRxPacket, std::move(rx)}, protocol::xbee::ApiMode::unescaped, bytes);
    }
  }
  store::Store store(path_);
  const auto rec = record(store, WireFormat::xbee, stream, paper_params());
  const auto result = replay_session(store, rec.session);
  EXPECT_EQ(result.samples_without_link, 0u);
  expect_identical_runs(store, *rec.live_run, result.run);
  std::map<std::string, std::int64_t> links;
  for (const auto& l : store.links(rec.session)) links[l.name] = l.id;
  const auto estimates = estimates_by_link(store, result.run);
  ASSERT_EQ(estimates.size(), 2u);
  EXPECT_TRUE(estimates.contains(links.at("imu0/0013A20040000001")));
  EXPECT_TRUE(estimates.contains(links.at("imu0/0013A200400000B2")));
}

TEST_F(Replay, WhatTheSessionHasNoLinkForIsCountedNotReplayed) {
  store::Store store(path_);
  nlohmann::json config;
  pipeline::add_recorded_links(config, {{"radio", WireFormat::xbee, protocol::Calibration::reference_board()}});
  const auto session = store.begin_session({.kind = "live", .config = config.dump(), .started_wall_ns = 0});
  const auto radio = store.add_link(session, "radio", "xbee", "");
  const auto other = store.add_link(session, "other", "imubridge", "");  // not in the config: no format to decode
  // Bytes of a radio the recorder never made a link for, as a damaged or hand-made store might hold.
  std::vector<std::uint8_t> bytes;
  for (std::uint16_t i = 0; i < 10; ++i) {
    protocol::xbee::RxPacket rx{.source64 = 0x0013A20040000042, .source16 = 0xFFFE, .options = 0x01, .payload = {}};
    protocol::imu::encode({.seq = i, .device_time_us = 5000u * i, .payload = protocol::imu::ImuRaw{}}, rx.payload);
    protocol::xbee::encode({protocol::xbee::kRxPacket, std::move(rx)}, protocol::xbee::ApiMode::unescaped, bytes);
  }
  store.append_chunk(session, radio, store::Direction::rx, 1, 1, bytes);
  store.append_chunk(session, other, store::Direction::rx, 2, 2, bytes);
  store.append_chunk(session, radio, store::Direction::tx, 3, 3, bytes);  // sent to the vehicle: not replayed
  const auto result = replay_session(store, session);
  EXPECT_EQ(result.samples_without_link, 10u);
  EXPECT_EQ(result.chunks_without_link, 1u);
  EXPECT_EQ(result.chunks, 1u);
  EXPECT_EQ(result.samples, 0u);
  EXPECT_EQ(result.estimates, 0u);
}

TEST_F(Replay, RefusesWhatItCannotReplayWithAClearError) {
  store::Store store(path_);
  const auto bare = store.begin_session({.kind = "live", .config = "{}", .started_wall_ns = 0});
  const auto expect_error = [&](std::int64_t session, const std::string& part) {
    try {
      replay_session(store, session);
      ADD_FAILURE() << "replayed session " << session;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
    }
  };
  expect_error(bare + 1, "no session");
  expect_error(bare, "records no links");
  nlohmann::json config;
  pipeline::add_recorded_links(config, {{"imu0", WireFormat::imubridge, protocol::Calibration::reference_board()}});
  const auto silent = store.begin_session({.kind = "live", .config = config.dump(), .started_wall_ns = 0});
  store.add_link(silent, "imu0", "imubridge", "");
  expect_error(silent, "no recorded bytes");
  EXPECT_TRUE(store.runs(silent).empty());
}

TEST_F(Replay, PacingChangesWhenChunksArriveNotWhichOrWhat) {
  store::Store store(path_);
  const auto rec = record(store, WireFormat::mavlink, serial_stream(WireFormat::mavlink, 0.5, true), {});
  const auto session = find_session(store, rec.session);
  const auto play = [&](std::optional<double> speed) {
    std::vector<std::pair<double, std::vector<std::uint8_t>>> seen;
    play_chunks(store, session, {.speed = speed},
                [&](const store::Chunk& c, double t_s) { seen.emplace_back(t_s, c.bytes); });
    return seen;
  };
  const auto unpaced = play(std::nullopt);
  EXPECT_FALSE(unpaced.empty());
  EXPECT_EQ(play(50.0), unpaced);
  EXPECT_THROW(play(0.0), std::invalid_argument);
  EXPECT_THROW(play(-1.0), std::invalid_argument);
}

}  // namespace
}  // namespace imubridge::replay
