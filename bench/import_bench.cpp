// Import throughput: `imubridge import ulog` and `import tlog` as importers::import_ulog / import_tlog run them, each
// iteration into a fresh SQLite store in a scratch directory, in IMU samples per second of CPU time (Google
// Benchmark's CPU column). Target: >= 1,000,000 samples/s for both. The *Read benchmarks run the file's reader alone
// (and for tlog, the reader plus one MAVLink decoder pass over every frame, what the import's survey of the log
// does), on the same files and counting the same samples, so the difference says what the store side costs.
// Inputs: a tlog written as `imubridge sim --protocol mavlink --tlog` writes one (the paper scenario, 520 s at 200 Hz:
// 104,000 HIGHRES_IMU samples); the PX4 sample log ../shared/data/ulog/sample.ulg beside the repository when present
// (IMUBRIDGE_ULOG_FILE overrides), else tests/data/ulog/sample_log_small.ulg.
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "bench/scratch_dir.hpp"
#include "protocol/mavlink.hpp"
#include "importers/tlog.hpp"
#include "importers/tlog_import.hpp"
#include "importers/ulog.hpp"
#include "importers/ulog_import.hpp"
#include "sim/frame_encoder.hpp"
#include "sim/scenario.hpp"

namespace imubridge::importers {
namespace {

namespace fs = std::filesystem;
using bench::ScratchDir;

constexpr double kTlogFlightSeconds = 520;                 // 104,000 samples at 200 Hz
constexpr std::uint64_t kEpochUs = 1'704'067'200'000'000;  // as `sim --tlog` stamps its records

fs::path ulog_file() {
  if (const char* file = std::getenv("IMUBRIDGE_ULOG_FILE")) return file;
  const fs::path shared = fs::path(IMUBRIDGE_SOURCE_DIR) / ".." / "shared" / "data" / "ulog" / "sample.ulg";
  if (fs::exists(shared)) return shared;
  return fs::path(IMUBRIDGE_SOURCE_DIR) / "tests" / "data" / "ulog" / "sample_log_small.ulg";
}

// The simulated flight's telemetry log, written once into a scratch directory that lives as long as the program.
const fs::path& tlog_file() {
  static const ScratchDir dir;
  static const fs::path path = [] {
    const fs::path p = dir.database().parent_path() / "flight.tlog";
    sim::MavlinkTelemetry telemetry;
    std::vector<std::vector<std::uint8_t>> frames;
    std::vector<std::uint8_t> bytes;
    sim::simulate(sim::make_scenario("paper", 1, kTlogFlightSeconds), [&](const sim::SimSample& s) {
      frames.clear();
      telemetry.encode(s, frames);
      const auto t = kEpochUs + static_cast<std::uint64_t>(std::llround(s.time_s * 1e6));
      for (const auto& frame : frames) tlog::append_record(bytes, t, frame);
    });
    std::ofstream(p, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    return p;
  }();
  return path;
}

// The samples one import of `file` gives, for the readers' benchmarks to count by.
template <typename Import>
std::uint64_t samples_of(Import import) {
  const ScratchDir dir;
  store::Store store(dir.database());
  return import(store).samples;
}

// Each iteration imports into a fresh store, timed from the import's start to the store closed (closing commits
// what is pending: part of the import); creating the scratch directory and the store is not timed. The samples of
// one import.
template <typename Import>
std::uint64_t import_into_fresh_stores(benchmark::State& state, Import import) {
  std::uint64_t samples = 0;
  for (auto _ : state) {
    state.PauseTiming();
    {
      const ScratchDir dir;
      auto store = std::make_unique<store::Store>(dir.database());
      state.ResumeTiming();
      samples = import(*store).samples;
      store.reset();
      state.PauseTiming();
    }
    state.ResumeTiming();
  }
  return samples;
}

void report(benchmark::State& state, std::uint64_t samples, std::uint64_t bytes) {
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * samples));
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * bytes));
  state.counters["samples"] = static_cast<double>(samples);
}

void BM_UlogImport(benchmark::State& state) {
  const fs::path file = ulog_file();
  const std::uint64_t samples =
      import_into_fresh_stores(state, [&](store::Store& store) { return import_ulog(store, {.file = file}); });
  report(state, samples, fs::file_size(file));
  state.SetLabel(file.filename().string());
}
BENCHMARK(BM_UlogImport)->Unit(benchmark::kMillisecond)->MinTime(2.0);

void BM_UlogRead(benchmark::State& state) {
  const fs::path file = ulog_file();
  const std::uint64_t samples =
      samples_of([&](store::Store& store) { return import_ulog(store, {.file = file, .reference = false}); });
  for (auto _ : state) {
    const ulog::Log log = ulog::read_file(file);
    benchmark::DoNotOptimize(log.topics.data());
  }
  report(state, samples, fs::file_size(file));
  state.SetLabel(file.filename().string());
}
BENCHMARK(BM_UlogRead)->Unit(benchmark::kMillisecond)->MinTime(1.0);

void BM_TlogImport(benchmark::State& state) {
  const fs::path& file = tlog_file();
  const std::uint64_t samples =
      import_into_fresh_stores(state, [&](store::Store& store) { return import_tlog(store, {.file = file}); });
  report(state, samples, fs::file_size(file));
}
BENCHMARK(BM_TlogImport)->Unit(benchmark::kMillisecond)->MinTime(2.0);

void BM_TlogRead(benchmark::State& state) {
  const fs::path& file = tlog_file();
  const std::uint64_t samples = samples_of([&](store::Store& store) { return import_tlog(store, {.file = file}); });
  for (auto _ : state) {
    const tlog::Log log = tlog::read_file(file);
    benchmark::DoNotOptimize(log.records.data());
  }
  report(state, samples, fs::file_size(file));
}
BENCHMARK(BM_TlogRead)->Unit(benchmark::kMillisecond)->MinTime(1.0);

// The reader and one decoder pass over every frame (the import's survey decodes each frame once; its recording
// through the session engine decodes each once more).
void BM_TlogReadAndDecode(benchmark::State& state) {
  const fs::path& file = tlog_file();
  const std::uint64_t samples = samples_of([&](store::Store& store) { return import_tlog(store, {.file = file}); });
  std::vector<protocol::mavlink::Message> out;
  for (auto _ : state) {
    const tlog::Log log = tlog::read_file(file);
    protocol::mavlink::Decoder decoder;
    std::uint64_t decoded = 0;
    for (const tlog::Record& r : log.records) {
      out.clear();
      decoder.feed(log.frame(r), out);
      for (const auto& m : out) decoded += protocol::mavlink::decode(m).has_value();
    }
    benchmark::DoNotOptimize(decoded);
  }
  report(state, samples, fs::file_size(file));
}
BENCHMARK(BM_TlogReadAndDecode)->Unit(benchmark::kMillisecond)->MinTime(1.0);

}  // namespace
}  // namespace imubridge::importers
