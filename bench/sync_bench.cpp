// imubridge sync's throughput: a recorded session (samples as the imubridge frame gives them, with the live run's
// estimate for each and a little reference) copied into a real, durable PostgreSQL server on this machine
// (tests/support/postgres_server.hpp) by archive::sync_to_archive, as `imubridge sync --to` does; then a rerun, which finds
// nothing to send. Each iteration syncs into a fresh database. N stations (Arg) sync at once, each its own store
// file and connection, into one archive, as a fleet's ground stations do. docs/performance.md, "Syncing to the
// archive".
#include <benchmark/benchmark.h>

#include <cmath>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "archive/archive_schema.hpp"
#include "archive/sync.hpp"
#include "bench/scratch_dir.hpp"
#include "store/store.hpp"
#include "tests/support/postgres_server.hpp"

namespace imubridge::archive {
namespace {

namespace fs = std::filesystem;

constexpr int kSamples = 200'000;  // 200 s of one 1 kHz IMU

test::PostgresServer& server() {
  static test::PostgresServer instance({.durable = true});  // fsync on: what a real archive pays per commit
  return instance;
}

// A session of kSamples samples, an estimate for each (a live run), and reference rows at 100 Hz.
void record(const fs::path& path) {
  store::Store store(path);
  const std::int64_t session = store.begin_session({.kind = "bench", .source = "sync_bench", .started_wall_ns = 1});
  const std::int64_t link = store.add_link(session, "imu0", "imubridge", "bench");
  const std::int64_t run = store.begin_run(session, {.kind = "live", .params_json = "{}"});
  for (int i = 0; i < kSamples; ++i) {
    const double t = i * 1e-3;
    protocol::Sample s;
    s.link_id = link;
    s.seq = static_cast<std::uint64_t>(i);
    s.device_time_us = 1000LL * i;
    s.recv_mono_ns = 1'000'000LL * i + 137;
    s.accel = {0.3 * std::sin(t), -0.2 * std::cos(1.3 * t), -9.80665 + 0.05 * std::sin(7 * t)};
    s.gyro = {0.01 * std::cos(t), 0.02 * std::sin(0.7 * t), -0.003 * t};
    s.mag = {21.0 + std::sin(t), -4.5, 43.0 + 0.01 * std::cos(t)};
    s.has_mag = true;
    s.temperature_c = 31.5 + 1e-4 * i;
    s.has_temperature = true;
    for (std::size_t k = 0; k < s.raw.size(); ++k) s.raw[k] = i * 10 + static_cast<int>(k);
    s.has_raw = true;
    store.append_sample(session, s);
    store.append_estimate(run, {.link_id = link,
                                .seq = s.seq,
                                .t_s = t,
                                .fx = s.accel[0],
                                .fy = s.accel[1],
                                .vx = std::sin(0.1 * t),
                                .vy = std::cos(0.1 * t),
                                .var_vx = 0.01 + 1e-7 * i,
                                .var_vy = 0.02 + 1e-7 * i});
    if (i % 10 == 0)
      store.append_reference(session, {.t_ns = 1'000'000LL * i, .position = {t, 2 * t, -1}, .quat_wxyz = {1, 0, 0, 0}});
  }
  store.end_session(session, 2);
}

const fs::path& store_file() {
  static bench::ScratchDir dir;
  static const fs::path path = [] {
    record(dir.database());
    return dir.database();
  }();
  return path;
}

std::string fresh_archive() {
  static int counter = 0;
  const std::string name = "bench_" + std::to_string(counter++);
  server().create_database(name);
  return server().url(name);
}

// Arg: stations syncing at once (each a copy of the same file under its own name).
void BM_SyncSession(benchmark::State& state) {
  const int stations = static_cast<int>(state.range(0));
  const fs::path& file = store_file();
  for (auto _ : state) {
    state.PauseTiming();
    const std::string url = fresh_archive();
    {
      PgConnection pg({.url = url});
      ensure_archive_schema(pg);  // once, as the first station's first sync does
    }
    state.ResumeTiming();
    std::vector<std::thread> threads;
    for (int s = 0; s < stations; ++s) {
      threads.emplace_back([&, s] {
        PgConnection pg({.url = url});
        sync_to_archive(file, pg, {.station = "gs" + std::to_string(s)});
      });
    }
    for (auto& t : threads) t.join();
  }
  state.SetItemsProcessed(state.iterations() * kSamples * stations);  // samples/s, each with its estimate
  state.counters["rows_per_sample"] = 2.1;                            // its estimate and a tenth of a reference row
}
BENCHMARK(BM_SyncSession)->Arg(1)->Arg(2)->Arg(4)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

// A rerun of a synced session: the archive's positions read, nothing sent.
void BM_RerunSendsNothing(benchmark::State& state) {
  const std::string url = fresh_archive();
  PgConnection pg({.url = url});
  sync_to_archive(store_file(), pg, {.station = "gs0"});
  for (auto _ : state) {
    const auto counts = sync_to_archive(store_file(), pg, {.station = "gs0"});
    if (counts.rows() != 0) state.SkipWithError("a rerun sent rows");
  }
}
BENCHMARK(BM_RerunSendsNothing)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace imubridge::archive
