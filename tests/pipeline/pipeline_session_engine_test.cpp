// The engine every session runs through: decoding, estimation and the fan-out to sinks, in order.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "pipeline/link_recorder.hpp"
#include "pipeline/recorded_session.hpp"
#include "pipeline/session_config.hpp"
#include "pipeline/session_engine.hpp"
#include "protocol/mavlink_messages.hpp"
#include "sim/frame_encoder.hpp"
#include "sim/scenario.hpp"
#include "store/store.hpp"
#include "tests/support/paper_params.hpp"
#include "tests/support/temp_dir.hpp"

namespace imubridge::pipeline {
namespace {

using test::paper_params;

// A simulated flight's wire bytes, cut into chunks of 100 bytes as a serial port might return them.
std::vector<std::vector<std::uint8_t>> flight_chunks(double seconds) {
  sim::FrameEncoder encoder(protocol::WireFormat::imubridge);
  std::vector<std::uint8_t> bytes;
  for (const auto& s : sim::simulate(sim::make_scenario("paper", 3, seconds))) encoder.encode(s, bytes);
  encoder.flush(bytes);
  std::vector<std::vector<std::uint8_t>> chunks;
  for (std::size_t i = 0; i < bytes.size(); i += 100) {
    chunks.emplace_back(bytes.begin() + static_cast<std::ptrdiff_t>(i),
                        bytes.begin() + static_cast<std::ptrdiff_t>(std::min(bytes.size(), i + 100)));
  }
  return chunks;
}

// Writes down every call, so the tests can check what each sink saw and in which order.
struct Recorder final : SessionSink {
  std::string name;
  std::vector<std::string>* log;
  std::vector<protocol::Sample> samples;
  std::vector<store::Estimate> estimates, final_estimates;
  std::size_t bytes = 0;

  Recorder(std::string n, std::vector<std::string>* l) : name(std::move(n)), log(l) {}
  void on_chunk(std::size_t link, const DecodedChunk& chunk) override {
    bytes += chunk.bytes.size();
    log->push_back(name + (chunk.end ? " end " : " bytes ") + std::to_string(link));
  }
  void on_sample(std::size_t link, const protocol::Sample& s, std::span<const store::Estimate> e,
                 std::int64_t) override {
    samples.push_back(s);
    estimates.insert(estimates.end(), e.begin(), e.end());
    log->push_back(name + " sample " + std::to_string(link) + " " + std::to_string(s.seq));
  }
  void on_final_estimates(const protocol::SourceKey& source, std::span<const store::Estimate> e) override {
    final_estimates.insert(final_estimates.end(), e.begin(), e.end());
    log->push_back(name + " final " + std::to_string(source.link));
  }
};

TEST(SessionEngine, GivesEverySinkTheDecodedSamplesAndTheStagesEstimatesInOrder) {
  const auto chunks = flight_chunks(2.0);
  std::vector<std::string> log;
  Recorder first("a", &log), second("b", &log);
  SessionEngine engine(std::make_unique<EstimationStage>(paper_params()));
  EXPECT_EQ(engine.add_link(LinkDecoder(protocol::WireFormat::imubridge, protocol::Calibration::reference_board())),
            0u);
  engine.add_sink(first);
  engine.add_sink(second);
  std::int64_t t = 0;
  for (const auto& chunk : chunks) {
    t += 1'000'000;
    engine.on_chunk(0, chunk, t, t);
  }
  engine.finish_link(0, t, t);
  engine.finish();

  // The same samples through a LinkDecoder and an EstimationStage by hand: what the engine must have done.
  LinkDecoder reference_decoder(protocol::WireFormat::imubridge, protocol::Calibration::reference_board());
  EstimationStage reference_stage(paper_params());
  std::vector<protocol::Sample> samples;
  std::vector<store::Estimate> estimates;
  t = 0;
  for (const auto& chunk : chunks) reference_decoder.feed(chunk, t += 1'000'000, samples);
  reference_decoder.finish(t, samples);
  for (const auto& s : samples) reference_stage.update(s, estimates);

  ASSERT_EQ(first.samples.size(), samples.size());
  ASSERT_GT(samples.size(), 300u);  // 2 s at the scenario's 200 Hz
  for (std::size_t i = 0; i < samples.size(); ++i) EXPECT_EQ(first.samples[i].seq, samples[i].seq);
  ASSERT_EQ(first.estimates.size(), estimates.size());
  for (std::size_t i = 0; i < estimates.size(); ++i) EXPECT_EQ(first.estimates[i], estimates[i]);
  EXPECT_EQ(second.estimates.size(), estimates.size());
  std::size_t total = 0;
  for (const auto& chunk : chunks) total += chunk.size();
  EXPECT_EQ(first.bytes, total);

  // Per chunk: every sink gets the chunk, then each sample goes to every sink in the order they were added; the
  // end of the stream comes the same way. Nothing waited for its axes, so nothing is released at the end.
  ASSERT_GE(log.size(), 4u);
  EXPECT_EQ(log[0], "a bytes 0");
  EXPECT_EQ(log[1], "b bytes 0");
  const auto first_sample =
      std::find_if(log.begin(), log.end(), [](const auto& l) { return l.starts_with("a sample"); });
  ASSERT_NE(first_sample, log.end());
  EXPECT_EQ(*std::next(first_sample), "b" + first_sample->substr(1));
  for (const auto& s : first.samples) EXPECT_EQ(s.source, protocol::SourceKey{.link = 0});
  const auto end = std::find(log.begin(), log.end(), "a end 0");
  ASSERT_NE(end, log.end());
  EXPECT_EQ(*std::next(end), "b end 0");
  EXPECT_TRUE(first.final_estimates.empty());
}

TEST(SessionEngine, ALinkWaitingForItsAxesReleasesItsEstimatesAtTheEnd) {
  // Auto axes on a flight too short to decide: every estimate waits until finish().
  const auto chunks = flight_chunks(0.3);
  std::vector<std::string> log;
  Recorder sink("a", &log);
  StageAxes axes;  // every link auto
  SessionEngine engine(std::make_unique<EstimationStage>(paper_params(), std::move(axes)));
  engine.add_link(LinkDecoder(protocol::WireFormat::imubridge, protocol::Calibration::reference_board()));
  engine.add_link(LinkDecoder(protocol::WireFormat::imubridge, protocol::Calibration::reference_board()));
  engine.add_sink(sink);
  for (const auto& chunk : chunks) engine.on_chunk(1, chunk, 0, 0);
  engine.finish_link(1, 0, 0);
  ASSERT_GT(sink.samples.size(), 50u);
  EXPECT_TRUE(sink.estimates.empty());
  engine.finish();
  EXPECT_EQ(sink.final_estimates.size(),
            sink.samples.size() - 2 * static_cast<std::size_t>(engine.stage()->delay_samples()));
  EXPECT_EQ(log.back(), "a final 1");  // released under the link that waited
}

// Writers without parameters (sim --db, the imports) run the engine without a stage: the sinks get every chunk and
// sample, and no estimate at all, not even the specific force a stage without parameters would give.
TEST(SessionEngine, WithoutAStageGivesTheSinksEverySampleAndNoEstimate) {
  const auto chunks = flight_chunks(2.0);
  const auto run = [&](std::unique_ptr<EstimationStage> stage) {
    std::vector<std::string> log;
    Recorder sink("a", &log);
    SessionEngine engine(std::move(stage));
    engine.add_link(LinkDecoder(protocol::WireFormat::imubridge, protocol::Calibration::reference_board()));
    engine.add_sink(sink);
    std::int64_t t = 0;
    for (const auto& chunk : chunks) {
      t += 1'000'000;
      engine.on_chunk(0, chunk, t, t);
    }
    engine.finish_link(0, t, t);
    engine.finish();
    EXPECT_NE(std::find(log.begin(), log.end(), "a end 0"), log.end());
    return sink;
  };
  const Recorder estimated = run(std::make_unique<EstimationStage>(estimator::ModelParams{}));
  ASSERT_GT(estimated.estimates.size(), 300u);  // what a stage, even one without parameters, makes of this flight

  const Recorder decoded = run(nullptr);
  ASSERT_EQ(decoded.samples.size(), estimated.samples.size());
  ASSERT_GT(decoded.samples.size(), 300u);
  for (std::size_t i = 0; i < decoded.samples.size(); ++i) {
    EXPECT_EQ(decoded.samples[i].seq, estimated.samples[i].seq);
    EXPECT_EQ(decoded.samples[i].accel, estimated.samples[i].accel);
  }
  EXPECT_EQ(decoded.bytes, estimated.bytes);
  EXPECT_TRUE(decoded.estimates.empty());
  EXPECT_TRUE(decoded.final_estimates.empty());
  EXPECT_EQ(SessionEngine(nullptr).stage(), nullptr);
}

// sim --db and the imports: a recorded session through its SessionRecording and an engine without a stage stores
// every chunk and every sample the sinks saw, and no run.
TEST(SessionEngine, RecordingWithoutAStageStoresChunksAndSamplesAndNoRun) {
  const auto chunks = flight_chunks(1.0);
  test::TempDir dir;
  store::Store store(dir / "s.db");
  const std::vector<SessionLink> links{
      {.recorded = {"imu0", protocol::WireFormat::imubridge, protocol::Calibration::reference_board(), "frd"},
       .device = "test"}};
  const RecordedSession recorded =
      begin_recorded_session(store, {.kind = "sim", .source = "test", .config = nlohmann::json::object()}, links);
  std::vector<std::string> log;
  Recorder sink("a", &log);
  SessionEngine engine(nullptr);
  engine.add_link(make_decoder(links[0].recorded));
  SessionRecording recording(store, recorded, links, engine);
  engine.add_sink(recording);
  engine.add_sink(sink);
  std::int64_t t = 0;
  for (const auto& chunk : chunks) {
    t += 1'000'000;
    engine.on_chunk(0, chunk, t, t);
  }
  engine.finish_link(0, t, t);
  engine.finish();
  end_recorded_session(store, recorded.id, t);

  std::size_t stored_chunks = 0;
  std::vector<protocol::Sample> stored;
  store.for_each_chunk(recorded.id, std::nullopt, [&](const store::Chunk&) { ++stored_chunks; });
  store.for_each_sample(recorded.id, std::nullopt, [&](const protocol::Sample& s) { stored.push_back(s); });
  EXPECT_EQ(stored_chunks, chunks.size());
  ASSERT_EQ(stored.size(), sink.samples.size());
  ASSERT_GT(stored.size(), 150u);
  for (std::size_t i = 0; i < stored.size(); ++i) EXPECT_EQ(stored[i].seq, sink.samples[i].seq);
  std::uint64_t frames = 0;
  for (const auto& [layer, counters] : engine.decoder(0).counters()) frames += counters.frames_out;
  EXPECT_EQ(frames, stored.size());  // the engine's decoder of the link decoded them
  EXPECT_TRUE(sink.estimates.empty());
  EXPECT_TRUE(store.runs(recorded.id).empty());
}

// The daemon's rotation: one engine, its decoder and stage running on, recorded into one store and then another. A
// frame cut between the two stores is decoded and stored in the second; each store's counters are its own share; and
// the estimates the two runs hold, one after the other, are those of a run recorded into one store.
TEST(SessionEngine, ARecordingCanEndAndAnotherBeginWhileTheEngineRunsOn) {
  const auto chunks = flight_chunks(1.0);
  test::TempDir dir;
  const std::vector<SessionLink> links{
      {.recorded = {"imu0", protocol::WireFormat::imubridge, protocol::Calibration::reference_board(), "frd"},
       .device = "test"}};
  const auto record = [&](const std::vector<std::string>& files, std::size_t switch_at) {
    SessionEngine engine(std::make_unique<EstimationStage>(paper_params()));
    engine.add_link(make_decoder(links[0].recorded));
    std::vector<std::int64_t> sessions;
    std::int64_t t = 0;
    for (std::size_t f = 0; f < files.size(); ++f) {
      store::Store store(dir / files[f]);
      const RecordedSession recorded =
          begin_recorded_session(store, {.kind = "live", .estimated_with = paper_params()}, links);
      sessions.push_back(recorded.id);
      SessionRecording recording(store, recorded, links, engine);
      engine.add_sink(recording);
      const std::size_t until = f + 1 < files.size() ? switch_at : chunks.size();
      for (std::size_t i = f == 0 ? 0 : switch_at; i < until; ++i) {
        t += 1'000;
        engine.on_chunk(0, chunks[i], t, t);
      }
      if (f + 1 == files.size()) engine.finish_link(0, t, t);
      recording.end(engine, t, t);
      engine.remove_sink(recording);
      end_recorded_session(store, recorded.id, t);
    }
    return sessions;
  };
  record({"one.db"}, 0);
  record({"first.db", "second.db"}, chunks.size() / 2);

  struct Held {
    std::vector<std::uint64_t> seqs;
    std::vector<store::Estimate> estimates;
    std::uint64_t bytes_in = 0;
  };
  const auto held = [&](const std::string& file) {
    const store::Store store(dir / file, {.read_only = true});
    Held h;
    store.for_each_sample(1, std::nullopt, [&](const protocol::Sample& s) { h.seqs.push_back(s.seq); });
    store.for_each_estimate(store.runs(1).at(0).id, [&](const store::Estimate& e) { h.estimates.push_back(e); });
    for (const store::Event& e : store.events(1)) {
      if (e.kind == "counters")
        h.bytes_in += nlohmann::json::parse(e.detail)["imubridge"]["bytes_in"].get<std::uint64_t>();
    }
    return h;
  };
  const Held one = held("one.db"), first = held("first.db"), second = held("second.db");
  std::vector<std::uint64_t> seqs = first.seqs;
  seqs.insert(seqs.end(), second.seqs.begin(), second.seqs.end());
  EXPECT_EQ(seqs, one.seqs) << "every frame decoded once, the one cut between the stores too";
  std::vector<store::Estimate> estimates = first.estimates;
  estimates.insert(estimates.end(), second.estimates.begin(), second.estimates.end());
  ASSERT_GT(one.estimates.size(), 150u);
  EXPECT_EQ(estimates, one.estimates) << "the filter ran on: bit for bit what one store holds";
  EXPECT_EQ(first.bytes_in + second.bytes_in, one.bytes_in);
  EXPECT_GT(second.bytes_in, 0u);
  EXPECT_LT(second.bytes_in, one.bytes_in);
}

TEST(SessionEngine, ARemovedSinkHearsNothingMore) {
  const auto chunks = flight_chunks(0.5);
  std::vector<std::string> log;
  Recorder kept("a", &log), removed("b", &log);
  SessionEngine engine(std::make_unique<EstimationStage>(paper_params()));
  engine.add_link(LinkDecoder(protocol::WireFormat::imubridge, protocol::Calibration::reference_board()));
  engine.add_sink(kept);
  engine.add_sink(removed);
  engine.on_chunk(0, chunks[0], 0, 0);
  const std::size_t heard = removed.bytes;
  engine.remove_sink(removed);
  for (std::size_t i = 1; i < chunks.size(); ++i) engine.on_chunk(0, chunks[i], 0, 0);
  EXPECT_EQ(removed.bytes, heard);
  EXPECT_GT(kept.bytes, heard);
}

// An autopilot standing 3 degrees rolled, its HIGHRES_IMU at 200 Hz for 20 s, one frame per chunk, and its land
// detector (EXTENDED_SYS_STATE, every 0.5 s): on the ground for 10 s, then in the air (still reading the stance: the
// drag law then reads its tilt as a speed). Another vehicle (system 2) on the same link says it is on the ground
// throughout; its detector is not this IMU's.
std::vector<std::vector<std::uint8_t>> standing_autopilot_chunks() {
  namespace mav = protocol::mavlink;
  const double g = 9.80665, roll = 0.05;
  std::vector<std::vector<std::uint8_t>> chunks;
  std::uint8_t seq = 0;
  for (std::uint32_t i = 0; i < 4000; ++i) {
    auto& chunk = chunks.emplace_back();
    mav::encode(mav::make_message(mav::HighresImu{.time_usec = 5000ull * i,
                                                  .xacc = 0.0f,
                                                  .yacc = static_cast<float>(-g * std::sin(roll)),
                                                  .zacc = static_cast<float>(-g * std::cos(roll))},
                                  {.seq = seq++}),
                chunk);
    if (i % 100 == 50) {
      const auto state = i < 2000 ? mav::LandedState::on_ground : mav::LandedState::in_air;
      mav::encode(
          mav::make_message(mav::ExtendedSysState{.landed_state = static_cast<std::uint8_t>(state)}, {.seq = seq++}),
          chunk);
      mav::encode(mav::make_message(
                      mav::ExtendedSysState{.landed_state = static_cast<std::uint8_t>(mav::LandedState::on_ground)},
                      {.sysid = 2}),
                  chunk);
    }
  }
  return chunks;
}

// The land detector a MAVLink link carries holds its estimates at rest while it says landed, and is recorded as the
// session's takeoff; without it (the same IMU frames alone) the stance reads as a speed.
TEST(SessionEngine, AnAutopilotsLandDetectorHoldsItsLinksVelocityAtRestAndIsRecorded) {
  const auto chunks = standing_autopilot_chunks();
  const SessionLink link{.recorded = {.name = "fc",
                                      .format = protocol::WireFormat::mavlink,
                                      .imu_axes = "frd",
                                      .mavlink_imu_lock = MavlinkImuLock{}},
                         .device = "test"};
  const auto run = [&](bool with_detector, store::Store* store) {
    SessionEngine engine(std::make_unique<EstimationStage>(paper_params(), StageAxes{.others = estimator::frd_axes()}));
    engine.add_link(make_decoder(link.recorded));
    std::vector<std::string> log;
    Recorder sink("a", &log);
    engine.add_sink(sink);
    std::optional<RecordedSession> recorded;
    std::optional<SessionRecording> recording;
    if (store) {
      recorded = begin_recorded_session(*store, {.kind = "live", .source = "test", .config = nlohmann::json::object()},
                                        {link});
      recording.emplace(*store, *recorded, std::vector<SessionLink>{link}, engine);
      engine.add_sink(*recording);
    }
    std::int64_t t = 0;
    for (const auto& chunk : chunks) {
      t += 5'000'000;
      // Without the detector: the IMU frame alone, the chunk's first.
      const std::size_t imu_frame = chunk[0] == 0xFD ? 12u + chunk[1] : 8u + chunk[1];
      engine.on_chunk(0, with_detector ? std::span(chunk) : std::span(chunk).first(imu_frame), t, t);
    }
    engine.finish_link(0, t, t);
    engine.finish();
    if (store) end_recorded_session(*store, recorded->id, t);
    return sink.estimates;
  };
  test::TempDir dir;
  store::Store store(dir / "s.db");
  const std::vector<store::Estimate> told = run(true, &store);
  const std::vector<store::Estimate> untold = run(false, nullptr);
  ASSERT_EQ(told.size(), untold.size());
  ASSERT_GT(told.size(), 3900u);
  std::size_t on_ground = 0;
  for (std::size_t i = 0; i < told.size(); ++i) {
    const store::Estimate& e = told[i];
    if (e.t_s > 1.0 && e.t_s < 10.0) {  // from the first detector message to take-off
      ++on_ground;
      ASSERT_LT(std::hypot(e.vx, e.vy), 0.02) << e.t_s;
      ASSERT_LT(e.var_vy, 0.05 * 0.05) << e.t_s;
      ASSERT_GT(std::abs(untold[i].vy), 0.5) << e.t_s;  // the mechanism off: the stance read as a speed
    }
  }
  EXPECT_GT(on_ground, 1500u);
  EXPECT_GT(std::abs(told.back().vy), 0.5);  // in the air, by the detector's word: the drag law reads again
  std::vector<store::Event> detector;
  for (const store::Event& e : store.events(1)) {
    if (e.kind == "takeoff" || e.kind == "landing") detector.push_back(e);
  }
  ASSERT_EQ(detector.size(), 1u);  // system 2's "on the ground" is not this IMU's
  EXPECT_EQ(detector[0].kind, "takeoff");
  EXPECT_EQ(detector[0].mono_ns, 2051LL * 5'000'000);  // the chunk that carried the first "in the air"
}

}  // namespace
}  // namespace imubridge::pipeline
