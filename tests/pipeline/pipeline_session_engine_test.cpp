// The engine every session runs through: decoding, estimation and the fan-out to sinks, in order.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "pipeline/record_and_decode.hpp"
#include "pipeline/recorded_session.hpp"
#include "pipeline/session_engine.hpp"
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
  void on_bytes(std::size_t link, std::span<const std::uint8_t> b, std::int64_t) override {
    bytes += b.size();
    log->push_back(name + " bytes " + std::to_string(link));
  }
  void on_sample(std::size_t link, const protocol::Sample& s, std::span<const store::Estimate> e,
                 std::int64_t) override {
    samples.push_back(s);
    estimates.insert(estimates.end(), e.begin(), e.end());
    log->push_back(name + " sample " + std::to_string(link) + " " + std::to_string(s.seq));
  }
  void on_final_estimates(std::span<const store::Estimate> e) override {
    final_estimates.assign(e.begin(), e.end());
    log->push_back(name + " final");
  }
};

TEST(SessionEngine, GivesEverySinkTheDecodedSamplesAndTheStagesEstimatesInOrder) {
  const auto chunks = flight_chunks(2.0);
  LinkDecoder decoder(protocol::WireFormat::imubridge, 7, protocol::Calibration::reference_board());
  DecodeOnly decoding(decoder);
  std::vector<std::string> log;
  Recorder first("a", &log), second("b", &log);
  SessionEngine engine(std::make_unique<EstimationStage>(paper_params()));
  engine.add_sink(first);
  engine.add_sink(second);
  std::int64_t t = 0;
  for (const auto& chunk : chunks) {
    t += 1'000'000;
    engine.on_chunk(0, decoding, chunk, t, t);
  }
  engine.finish_link(0, decoding, t, t);
  engine.finish();

  // The same samples through a LinkDecoder and an EstimationStage by hand: what the engine must have done.
  LinkDecoder reference_decoder(protocol::WireFormat::imubridge, 7, protocol::Calibration::reference_board());
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

  // Per chunk: every sink gets the bytes, then each sample goes to every sink in the order they were added.
  ASSERT_GE(log.size(), 4u);
  EXPECT_EQ(log[0], "a bytes 0");
  EXPECT_EQ(log[1], "b bytes 0");
  const auto first_sample =
      std::find_if(log.begin(), log.end(), [](const auto& l) { return l.starts_with("a sample"); });
  ASSERT_NE(first_sample, log.end());
  EXPECT_EQ(*std::next(first_sample), "b" + first_sample->substr(1));
  EXPECT_EQ(log[log.size() - 2], "a final");
  EXPECT_EQ(log.back(), "b final");
}

TEST(SessionEngine, ALinkWaitingForItsAxesReleasesItsEstimatesAtTheEnd) {
  // Auto axes on a flight too short to decide: every estimate waits until finish().
  const auto chunks = flight_chunks(0.3);
  LinkDecoder decoder(protocol::WireFormat::imubridge, 1, protocol::Calibration::reference_board());
  DecodeOnly decoding(decoder);
  std::vector<std::string> log;
  Recorder sink("a", &log);
  StageAxes axes;  // every link auto
  SessionEngine engine(std::make_unique<EstimationStage>(paper_params(), std::move(axes)));
  engine.add_sink(sink);
  for (const auto& chunk : chunks) engine.on_chunk(0, decoding, chunk, 0, 0);
  engine.finish_link(0, decoding, 0, 0);
  ASSERT_GT(sink.samples.size(), 50u);
  EXPECT_TRUE(sink.estimates.empty());
  engine.finish();
  EXPECT_EQ(sink.final_estimates.size(),
            sink.samples.size() - 2 * static_cast<std::size_t>(engine.stage()->delay_samples()));
}

// Writers without parameters (sim --db, the imports) run the engine without a stage: the sinks get every chunk and
// sample, and no estimate at all, not even the specific force a stage without parameters would give.
TEST(SessionEngine, WithoutAStageGivesTheSinksEverySampleAndNoEstimate) {
  const auto chunks = flight_chunks(2.0);
  const auto run = [&](std::unique_ptr<EstimationStage> stage) {
    LinkDecoder decoder(protocol::WireFormat::imubridge, 7, protocol::Calibration::reference_board());
    DecodeOnly decoding(decoder);
    std::vector<std::string> log;
    Recorder sink("a", &log);
    SessionEngine engine(std::move(stage));
    engine.add_sink(sink);
    std::int64_t t = 0;
    for (const auto& chunk : chunks) {
      t += 1'000'000;
      engine.on_chunk(0, decoding, chunk, t, t);
    }
    engine.finish_link(0, decoding, t, t);
    engine.finish();
    EXPECT_EQ(log.back(), "a final");
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

// sim --db and the imports: a recorded session through RecordAndDecode and an engine without a stage stores every
// chunk and every sample the sinks saw, and no run.
TEST(SessionEngine, RecordingWithoutAStageStoresChunksAndSamplesAndNoRun) {
  const auto chunks = flight_chunks(1.0);
  test::TempDir dir;
  store::Store store(dir / "s.db");
  RecordedSession recorded = begin_recorded_session(
      store, {.kind = "sim", .source = "test", .config = nlohmann::json::object()},
      {{.recorded = {"imu0", protocol::WireFormat::imubridge, protocol::Calibration::reference_board(), "frd"},
        .device = "test"}});
  RecordAndDecode recording(std::move(recorded.recorders[0]));
  std::vector<std::string> log;
  Recorder sink("a", &log);
  SessionEngine engine(nullptr);
  engine.add_sink(sink);
  std::int64_t t = 0;
  for (const auto& chunk : chunks) {
    t += 1'000'000;
    engine.on_chunk(0, recording, chunk, t, t);
  }
  engine.finish_link(0, recording, t, t);
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
  for (const auto& [layer, counters] : recording.decoder().counters()) frames += counters.frames_out;
  EXPECT_EQ(frames, stored.size());  // the recorder's own decoder decoded them
  EXPECT_TRUE(sink.estimates.empty());
  EXPECT_TRUE(store.runs(recorded.id).empty());
}

TEST(SessionEngine, ARemovedSinkHearsNothingMore) {
  const auto chunks = flight_chunks(0.5);
  LinkDecoder decoder(protocol::WireFormat::imubridge, 1, protocol::Calibration::reference_board());
  DecodeOnly decoding(decoder);
  std::vector<std::string> log;
  Recorder kept("a", &log), removed("b", &log);
  SessionEngine engine(std::make_unique<EstimationStage>(paper_params()));
  engine.add_sink(kept);
  engine.add_sink(removed);
  engine.on_chunk(0, decoding, chunks[0], 0, 0);
  const std::size_t heard = removed.bytes;
  engine.remove_sink(removed);
  for (std::size_t i = 1; i < chunks.size(); ++i) engine.on_chunk(0, decoding, chunks[i], 0, 0);
  EXPECT_EQ(removed.bytes, heard);
  EXPECT_GT(kept.bytes, heard);
}

}  // namespace
}  // namespace imubridge::pipeline
