// Replay throughput at --speed max, through the full pipeline with storage: chunks read from the store, decoded,
// estimated and the estimates stored as a new run. Target: >= 500,000 samples/s on one core. The BM_Stage*
// benchmarks time each stage alone on the same flight, so their ns per sample give each stage's share.
#include <benchmark/benchmark.h>
#include <stdlib.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "pipeline/estimation_stage.hpp"
#include "pipeline/link_decoder.hpp"
#include "pipeline/link_recorder.hpp"
#include "pipeline/session_config.hpp"
#include "replay/replayer.hpp"
#include "sim/frame_encoder.hpp"
#include "sim/scenario.hpp"

namespace imubridge::replay {
namespace {

namespace fs = std::filesystem;

constexpr double kFlightSeconds = 60;  // 12,000 samples at 200 Hz

class ScratchDir {
 public:
  ScratchDir() {
    std::string pattern = (fs::temp_directory_path() / "imubridge-replay-bench-XXXXXX").string();
    if (mkdtemp(pattern.data()) == nullptr) throw std::runtime_error("mkdtemp failed");
    path_ = pattern;
  }
  ~ScratchDir() { fs::remove_all(path_); }
  fs::path database() const { return path_ / "bench.db"; }

 private:
  fs::path path_;
};

estimator::ModelParams paper_params() {  // identified parameters: the estimator does its full work
  estimator::ModelParams p;
  p.full.lever_arm = {sim::kPaperR * std::cos(sim::kPaperBeta), 0.0, -sim::kPaperR * std::sin(sim::kPaperBeta)};
  p.full.mounting = {0.0, sim::kPaperAlpha, 0.0};
  p.full.drag_quadratic = {sim::kPaperMu, sim::kPaperMu};
  return p;
}

// The paper's flight recorded as `imubridge sim --db` records it: one imubridge frame per chunk. Returns the session.
std::int64_t record_flight(store::Store& store) {
  const auto calibration = protocol::Calibration::reference_board();
  nlohmann::json config;
  pipeline::add_recorded_links(config, {{"imu0", protocol::WireFormat::imubridge, calibration}});
  const auto session = store.begin_session({.kind = "sim", .config = config.dump(), .started_wall_ns = 0});
  const auto link = store.add_link(session, "imu0", "imubridge", "bench");
  pipeline::LinkRecorder recorder(store, session, link, "imu0", protocol::WireFormat::imubridge, calibration);
  sim::FrameEncoder encoder(protocol::WireFormat::imubridge);
  std::vector<std::uint8_t> bytes;
  std::vector<protocol::Sample> samples;
  sim::simulate(sim::make_scenario("paper", 1, kFlightSeconds), [&](const sim::SimSample& s) {
    bytes.clear();
    samples.clear();
    encoder.encode(s, bytes);
    const auto t = std::llround(s.time_s * 1e9);
    recorder.on_chunk(bytes, t, t, samples);
  });
  store.commit();
  return session;
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

void BM_StageReadChunks(benchmark::State& state) {
  const store::Store store(flight().dir.database(), {.read_only = true});
  for (auto _ : state) {
    std::size_t bytes = 0;
    store.for_each_chunk(flight().session, std::nullopt, [&](const store::Chunk& c) { bytes += c.bytes.size(); });
    benchmark::DoNotOptimize(bytes);
  }
  per_sample(state);
}
BENCHMARK(BM_StageReadChunks)->Unit(benchmark::kMillisecond);

void BM_StageDecode(benchmark::State& state) {
  std::vector<protocol::Sample> out;
  out.reserve(flight().samples.size());
  for (auto _ : state) {
    out.clear();
    pipeline::LinkDecoder decoder(protocol::WireFormat::imubridge, 1, protocol::Calibration::reference_board());
    for (const auto& c : flight().chunks) decoder.feed(c.bytes, c.recv_mono_ns, out);
    benchmark::DoNotOptimize(out.data());
  }
  per_sample(state);
}
BENCHMARK(BM_StageDecode)->Unit(benchmark::kMillisecond);

void BM_StageEstimate(benchmark::State& state) {
  for (auto _ : state) {
    pipeline::EstimationStage stage(paper_params());
    for (const auto& s : flight().samples) benchmark::DoNotOptimize(stage.update(s));
  }
  per_sample(state);
}
BENCHMARK(BM_StageEstimate)->Unit(benchmark::kMillisecond);

void BM_StageStoreEstimates(benchmark::State& state) {
  store::Store store(flight().dir.database());
  for (auto _ : state) {
    const auto run = store.begin_run(flight().session, {.kind = "bench"});
    for (const auto& e : flight().estimates) {
      store.append_estimate(run, e);
      store.commit_if_due(std::chrono::steady_clock::now());
    }
    store.commit();
  }
  per_sample(state);
}
BENCHMARK(BM_StageStoreEstimates)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace imubridge::replay
