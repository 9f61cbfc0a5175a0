// Sample ingest: through the Store (WAL, batched commits, foreign-key checks) against the floor SQLite allows, a bare
// loop of the same INSERT with one prepared statement in one transaction, into the same table of the same file.
// Target: Store >= 500,000 samples/s and >= 0.7 of the bare loop.
#include <benchmark/benchmark.h>
#include <sqlite3.h>
#include <stdlib.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

#include "store/store.hpp"

namespace imubridge::store {
namespace {

namespace fs = std::filesystem;

constexpr int kSamplesPerIteration = 10000;

// A scratch directory for one benchmark's database, removed afterwards.
class ScratchDir {
 public:
  ScratchDir() {
    std::string pattern = (fs::temp_directory_path() / "imubridge-store-bench-XXXXXX").string();
    if (mkdtemp(pattern.data()) == nullptr) throw std::runtime_error("mkdtemp failed");
    path_ = pattern;
  }
  ~ScratchDir() { fs::remove_all(path_); }
  fs::path database() const { return path_ / "bench.db"; }

 private:
  fs::path path_;
};

// A full row, as the imubridge frame gives it: SI values, magnetometer, temperature and raw counts.
std::vector<protocol::Sample> samples(std::uint32_t link) {
  std::vector<protocol::Sample> samples(kSamplesPerIteration);
  for (int i = 0; i < kSamplesPerIteration; ++i) {
    protocol::Sample& s = samples[static_cast<std::size_t>(i)];
    s.link_id = link;
    s.seq = static_cast<std::uint64_t>(i);
    s.device_time_us = 1000LL * i;
    s.recv_mono_ns = 1'000'000LL * i;
    s.accel = {0.01 * i, -0.02 * i, -9.80665};
    s.gyro = {0.001 * i, 0.002, -0.003 * i};
    s.mag = {21.0, -4.5, 43.0 + 0.01 * i};
    s.has_mag = true;
    s.temperature_c = 31.5;
    s.has_temperature = true;
    for (std::size_t k = 0; k < s.raw.size(); ++k) s.raw[k] = i * 10 + static_cast<int>(k);
    s.has_raw = true;
  }
  return samples;
}

// A database holding one session with one link, as the Store creates it; returns the link id (the session's is 1).
std::uint32_t prepare(const fs::path& path) {
  Store store(path);
  return static_cast<std::uint32_t>(store.add_link(store.begin_session({.kind = "bench"}), "imu0", "imubridge", ""));
}

void BM_StoreIngest(benchmark::State& state) {
  ScratchDir dir;
  const std::uint32_t link = prepare(dir.database());
  const auto rows = samples(link);
  Store store(dir.database());
  for (auto _ : state) {
    for (const auto& sample : rows) {
      store.append_sample(1, sample);
      store.commit_if_due(std::chrono::steady_clock::now());  // as the daemon does after every read
    }
  }
  store.commit();
  state.SetItemsProcessed(state.iterations() * kSamplesPerIteration);
}
BENCHMARK(BM_StoreIngest)->Unit(benchmark::kMillisecond);

// Plain SQLite calls, on purpose: this is the yardstick the Store is measured against. Return codes are checked
// only where a failure would make the numbers meaningless.
void BM_BareInsertLoop(benchmark::State& state) {
  ScratchDir dir;
  const std::uint32_t link = prepare(dir.database());
  const auto rows = samples(link);
  sqlite3* db = nullptr;
  sqlite3_stmt* insert = nullptr;
  if (sqlite3_open(dir.database().c_str(), &db) != SQLITE_OK ||
      sqlite3_prepare_v2(db,
                         "INSERT INTO samples (session_id, link_id, seq, device_time_us, recv_mono_ns, ax, ay, az, "
                         "gx, gy, gz, mx, my, mz, temperature_c, raw) "
                         "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16)",
                         -1, &insert, nullptr) != SQLITE_OK) {
    state.SkipWithError(sqlite3_errmsg(db));
    sqlite3_close(db);
    return;
  }
  for (auto _ : state) {
    sqlite3_exec(db, "BEGIN", nullptr, nullptr, nullptr);
    for (const auto& s : rows) {
      sqlite3_bind_int64(insert, 1, 1);
      sqlite3_bind_int64(insert, 2, s.link_id);
      sqlite3_bind_int64(insert, 3, static_cast<sqlite3_int64>(s.seq));
      sqlite3_bind_int64(insert, 4, s.device_time_us);
      sqlite3_bind_int64(insert, 5, s.recv_mono_ns);
      for (int k = 0; k < 3; ++k) {
        sqlite3_bind_double(insert, 6 + k, s.accel[k]);
        sqlite3_bind_double(insert, 9 + k, s.gyro[k]);
        sqlite3_bind_double(insert, 12 + k, s.mag[k]);
      }
      sqlite3_bind_double(insert, 15, s.temperature_c);
      sqlite3_bind_blob(insert, 16, s.raw.data(), sizeof(s.raw), SQLITE_STATIC);  // host order: fine for a yardstick
      if (sqlite3_step(insert) != SQLITE_DONE) state.SkipWithError(sqlite3_errmsg(db));
      sqlite3_reset(insert);
    }
    if (sqlite3_exec(db, "COMMIT", nullptr, nullptr, nullptr) != SQLITE_OK) state.SkipWithError(sqlite3_errmsg(db));
  }
  sqlite3_finalize(insert);
  sqlite3_close(db);
  state.SetItemsProcessed(state.iterations() * kSamplesPerIteration);
}
BENCHMARK(BM_BareInsertLoop)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace imubridge::store
