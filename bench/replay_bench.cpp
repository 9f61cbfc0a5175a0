// Replay throughput at --speed max, through the full pipeline with storage: chunks read from the store, decoded,
// estimated and the estimates stored as a new run. Target: >= 500,000 samples/s on one core (CPU time).
// BM_ReplayStageShares times each stage alone on the same flight and gives its share of the whole.
#include <benchmark/benchmark.h>
#include <time.h>

#include <chrono>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench/scratch_dir.hpp"
#include "pipeline/estimation_stage.hpp"
#include "pipeline/link_decoder.hpp"
#include "pipeline/link_recorder.hpp"
#include "pipeline/session_config.hpp"
#include "replay/replayer.hpp"
#include "sim/frame_encoder.hpp"
#include "sim/scenario.hpp"

namespace imubridge::replay {
namespace {

constexpr double kFlightSeconds = 60;  // 12,000 samples at 200 Hz

using bench::ScratchDir;

estimator::ModelParams paper_params() {  // identified parameters: the estimator does its full work
  estimator::ModelParams p;
  p.full.lever_arm = {sim::kPaperR * std::cos(sim::kPaperBeta), 0.0, -sim::kPaperR * std::sin(sim::kPaperBeta)};
  p.full.mounting = {0.0, sim::kPaperAlpha, 0.0};
  p.full.drag_quadratic = {sim::kPaperMu, sim::kPaperMu};
  return p;
}

// The paper's flight recorded as `imubridge sim --db` records it: one imubridge frame per chunk. Returns the session.
std::int64_t record_flight(store::Store& store) {
  const std::vector<pipeline::SessionLink> links{
      {.recorded = {"imu0", protocol::WireFormat::imubridge, protocol::Calibration::reference_board()},
       .device = "bench"}};
  const pipeline::RecordedSession session =
      pipeline::begin_recorded_session(store, {.kind = "sim", .started_wall_ns = 0}, links);
  pipeline::SessionEngine engine(nullptr);
  engine.add_link(pipeline::make_decoder(links[0].recorded));
  pipeline::SessionRecording recording(store, session, links, engine);
  engine.add_sink(recording);
  sim::FrameEncoder encoder(protocol::WireFormat::imubridge);
  std::vector<std::uint8_t> bytes;
  sim::simulate(sim::make_scenario("paper", 1, kFlightSeconds), [&](const sim::SimSample& s) {
    bytes.clear();
    encoder.encode(s, bytes);
    const auto t = std::llround(s.time_s * 1e9);
    engine.on_chunk(0, bytes, t, t);
  });
  store.commit();
  return session.id;
}

struct Flight {
  ScratchDir dir;
  std::int64_t session = 0;
  std::vector<store::Chunk> chunks;
  std::vector<protocol::Sample> samples;
  std::vector<store::Estimate> estimates;

  Flight() {
    store::Store store(dir.database());
    session = record_flight(store);
    store.for_each_chunk(session, std::nullopt, [&](const store::Chunk& c) { chunks.push_back(c); });
    store.for_each_sample(session, std::nullopt, [&](const protocol::Sample& s) { samples.push_back(s); });
    pipeline::EstimationStage stage(paper_params());
    for (const auto& s : samples) {
      if (const auto e = stage.update(s)) estimates.push_back(*e);
    }
  }
};

const Flight& flight() {
  static const Flight f;
  return f;
}

void per_sample(benchmark::State& state) {
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(flight().samples.size()));
}

void BM_ReplayFullPipeline(benchmark::State& state) {
  store::Store store(flight().dir.database());
  const ReplayOptions options{.params = paper_params()};
  for (auto _ : state) benchmark::DoNotOptimize(replay_session(store, flight().session, options));
  per_sample(state);
}
BENCHMARK(BM_ReplayFullPipeline)->Unit(benchmark::kMillisecond);

// Thread CPU time: the target (docs/performance.md, "Replay") is for one core, and other processes on the machine
// do not inflate it.
std::int64_t thread_cpu_ns() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return std::int64_t{t.tv_sec} * 1'000'000'000 + t.tv_nsec;
}

// The whole replay, then each of its stages alone over the same flight, in the same iteration. Counters: each stage's
// CPU time per sample (<stage>_ns) and its share of the four stages' sum (<stage>_%); replay_ns is the whole replay's
// CPU time per sample, for comparison with stages_ns (alone, a stage runs with warm caches of its own).
void BM_ReplayStageShares(benchmark::State& state) {
  store::Store store(flight().dir.database());
  const ReplayOptions options{.params = paper_params()};
  std::vector<protocol::Sample> samples;
  samples.reserve(flight().samples.size());
  std::map<std::string, std::int64_t> cpu_ns;
  const auto timed = [&cpu_ns](const std::string& stage, const auto& work) {
    const std::int64_t start = thread_cpu_ns();
    work();
    cpu_ns[stage] += thread_cpu_ns() - start;
  };
  for (auto _ : state) {
    timed("replay", [&] { benchmark::DoNotOptimize(replay_session(store, flight().session, options)); });
    timed("read", [&] {  // the chunks from the store
      std::size_t bytes = 0;
      store.for_each_chunk(flight().session, std::nullopt, [&](const store::Chunk& c) { bytes += c.bytes.size(); });
      benchmark::DoNotOptimize(bytes);
    });
    timed("decode", [&] {
      samples.clear();
      pipeline::LinkDecoder decoder(protocol::WireFormat::imubridge, protocol::Calibration::reference_board());
      for (const auto& c : flight().chunks) decoder.feed(c.bytes, c.recv_mono_ns, samples);
      benchmark::DoNotOptimize(samples.data());
    });
    timed("estimate", [&] {
      pipeline::EstimationStage stage(paper_params());
      for (const auto& s : flight().samples) benchmark::DoNotOptimize(stage.update(s));
    });
    timed("store", [&] {  // the estimates into a new run, committed as the replay commits them
      const auto run = store.begin_run(flight().session, {.kind = "bench"});
      for (const auto& e : flight().estimates) {
        store.append_estimate(run, e);
        store.commit_if_due(std::chrono::steady_clock::now());
      }
      store.commit();
    });
  }
  const auto samples_done = static_cast<double>(state.iterations() * flight().samples.size());
  const auto per_sample = [&](const char* stage) { return static_cast<double>(cpu_ns[stage]) / samples_done; };
  double stages_ns = 0;
  for (const char* stage : {"read", "decode", "estimate", "store"}) stages_ns += per_sample(stage);
  for (const char* stage : {"read", "decode", "estimate", "store"}) {
    state.counters[std::string(stage) + "_ns"] = per_sample(stage);
    state.counters[std::string(stage) + "_%"] = 100 * per_sample(stage) / stages_ns;
  }
  state.counters["stages_ns"] = stages_ns;
  state.counters["replay_ns"] = per_sample("replay");
  state.counters["replay_samples/s"] = 1e9 / per_sample("replay");
}
BENCHMARK(BM_ReplayStageShares)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace imubridge::replay
