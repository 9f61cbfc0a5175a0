// Sample ingest: through the Store (WAL, batched commits, foreign-key checks) against the floor SQLite allows, a bare
// loop of the same INSERT with one prepared statement in one transaction, into the same table of the same file.
// Target: Store >= 500,000 samples/s and >= 0.7 of the bare loop.
// Estimates (what a replay writes): through the Store, and bare INSERTs of 1 to 128 rows per statement, the
// measurement behind Store::kRowsPerStatement.
#include <benchmark/benchmark.h>
#include <sqlite3.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

#include "bench/scratch_dir.hpp"
#include "store/store.hpp"

namespace imubridge::store {
namespace {

namespace fs = std::filesystem;

constexpr int kSamplesPerIteration = 10000;

using bench::ScratchDir;

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
  return store.add_link(store.begin_session({.kind = "bench"}), "imu0", "imubridge", "");
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

// One session, link and run, as the Store creates them; returns the link id (the run's is 1).
std::int64_t prepare_run(const fs::path& path) {
  Store store(path);
  const std::int64_t session = store.begin_session({.kind = "bench"});
  const std::int64_t link = store.add_link(session, "imu0", "imubridge", "");
  store.begin_run(session, {.kind = "bench"});
  return link;
}

std::vector<Estimate> estimates(std::int64_t link) {
  std::vector<Estimate> estimates(kSamplesPerIteration);
  for (int i = 0; i < kSamplesPerIteration; ++i) {
    const double x = 0.001 * i;
    estimates[static_cast<std::size_t>(i)] = {.link_id = link,
                                              .seq = static_cast<std::uint64_t>(i),
                                              .t_s = 0.005 * i,
                                              .fx = 0.3 + x,
                                              .fy = -0.2 - x,
                                              .vx = 1.5 * x,
                                              .vy = -0.5 * x,
                                              .var_vx = 0.01 + x,
                                              .var_vy = 0.02 + x};
  }
  return estimates;
}

void BM_StoreEstimates(benchmark::State& state) {
  ScratchDir dir;
  const auto rows = estimates(prepare_run(dir.database()));
  Store store(dir.database());
  for (auto _ : state) {
    for (const auto& e : rows) {
      store.append_estimate(1, e);
      store.commit_if_due(std::chrono::steady_clock::now());
    }
  }
  store.commit();
  state.SetItemsProcessed(state.iterations() * kSamplesPerIteration);
}
BENCHMARK(BM_StoreEstimates)->Unit(benchmark::kMillisecond);

// INSERT ... VALUES (...), (...), ... with state.range(0) rows per statement, foreign keys on as in the Store.
void BM_BareEstimateInsert(benchmark::State& state) {
  const auto rows_per_statement = static_cast<std::size_t>(state.range(0));
  ScratchDir dir;
  const auto rows = estimates(prepare_run(dir.database()));
  std::string sql = "INSERT INTO estimates (run_id, link_id, seq, t_s, fx, fy, vx, vy, var_vx, var_vy) VALUES ";
  for (std::size_t r = 0; r < rows_per_statement; ++r)
    sql += r == 0 ? "(?,?,?,?,?,?,?,?,?,?)" : ",(?,?,?,?,?,?,?,?,?,?)";
  sqlite3* db = nullptr;
  sqlite3_stmt* insert = nullptr;
  if (sqlite3_open(dir.database().c_str(), &db) != SQLITE_OK ||
      sqlite3_exec(db, "PRAGMA foreign_keys = ON", nullptr, nullptr, nullptr) != SQLITE_OK ||
      sqlite3_prepare_v2(db, sql.c_str(), -1, &insert, nullptr) != SQLITE_OK) {
    state.SkipWithError(sqlite3_errmsg(db));
    sqlite3_close(db);
    return;
  }
  for (auto _ : state) {
    sqlite3_exec(db, "BEGIN", nullptr, nullptr, nullptr);
    for (std::size_t first = 0; first + rows_per_statement <= rows.size(); first += rows_per_statement) {
      int column = 1;
      for (std::size_t i = first; i < first + rows_per_statement; ++i) {
        const Estimate& e = rows[i];
        sqlite3_bind_int64(insert, column++, 1);
        sqlite3_bind_int64(insert, column++, e.link_id);
        sqlite3_bind_int64(insert, column++, static_cast<sqlite3_int64>(e.seq));
        for (double v : {e.t_s, e.fx, e.fy, e.vx, e.vy, e.var_vx, e.var_vy}) sqlite3_bind_double(insert, column++, v);
      }
      if (sqlite3_step(insert) != SQLITE_DONE) state.SkipWithError(sqlite3_errmsg(db));
      sqlite3_reset(insert);
    }
    if (sqlite3_exec(db, "COMMIT", nullptr, nullptr, nullptr) != SQLITE_OK) state.SkipWithError(sqlite3_errmsg(db));
  }
  sqlite3_finalize(insert);
  sqlite3_close(db);
  const auto rows_written = rows.size() / rows_per_statement * rows_per_statement;
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(rows_written));
}
BENCHMARK(BM_BareEstimateInsert)->Arg(1)->Arg(8)->Arg(16)->Arg(32)->Arg(64)->Arg(128)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace imubridge::store
