#pragma once
// The session store: one SQLite file keeping every raw byte chunk, decoded sample, event, pipeline run, estimate and
// reference pose of the sessions recorded into it. Writes are batched in one open transaction committed at least
// every commit_interval, so data is durable at most 200 ms (the default) after it was appended. A Store is used by
// one thread at a time. Layout and example queries: docs/storage.md.
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <set>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "protocol/sample.hpp"
#include "store/error.hpp"
#include "store/records.hpp"
#include "store/sqlite.hpp"
#include "store/wal_checkpointer.hpp"

namespace imubridge::store {

struct StoreOptions {
  // commit_if_due() commits once this much time has passed since its previous commit.
  std::chrono::milliseconds commit_interval{200};
  // A batch reaching this many rows is committed at once, whatever the time.
  std::size_t max_batch_rows = 100000;
  // For readers (replay, export): SQLite opens the file read-only, so the Store cannot change it; writes throw.
  bool read_only = false;
  // > 0: checkpoint the write-ahead log from a thread of its own at this interval (wal_checkpointer.hpp) instead of
  // inside whichever commit crosses SQLite's threshold, so a recorder's commits never wait for an fsync.
  std::chrono::milliseconds background_checkpoint{0};
};

class Store {
 public:
  using Options = StoreOptions;

  // Opens or creates the database at `path`, migrating an older schema. Throws StoreError if the file is not an
  // imubridge database, was written by a newer imubridge, or cannot be opened.
  explicit Store(const std::filesystem::path& path, Options options = {});
  Store(const Store&) = delete;
  Store& operator=(const Store&) = delete;
  // Commits what is pending. A failure here can only be reported on stderr: call commit() first to handle it.
  ~Store();

  // Writing. Rows join the open batch; sessions, links and runs are committed at once since others refer to them.
  // A write that fails throws StoreError. A row the schema rejects (unknown session, link or run) is refused alone;
  // any other failure (disk full, I/O error) rolls back the batch, and the message says how many rows were lost.
  std::int64_t begin_session(const SessionInfo& info);
  void end_session(std::int64_t session, std::int64_t ended_wall_ns);
  std::int64_t add_link(std::int64_t session, std::string_view name, std::string_view protocol,
                        std::string_view device);
  void append_chunk(std::int64_t session, std::int64_t link, Direction direction, std::int64_t recv_mono_ns,
                    std::int64_t recv_wall_ns, std::span<const std::uint8_t> bytes);
  void append_sample(std::int64_t session, const protocol::Sample& sample);  // sample.link_id names the link
  void append_event(std::int64_t session, const Event& event);
  std::int64_t begin_run(std::int64_t session, const RunInfo& info);
  // Estimates come at the sample rate, so they are written kEstimateBatchRows to a statement: the first row of each
  // (run, link) is written at once, so an unknown run or link fails here; the others wait in memory until a batch is
  // full or anything commits. They count as appended (pending_rows) and readers see them.
  void append_estimate(std::int64_t run, const Estimate& estimate);
  void append_reference(std::int64_t session, const ReferenceRow& row);

  // Commits the batch if rows are pending and commit_interval has passed since this function's previous commit
  // (its first commit happens at once). Call it often, with the current time; returns whether it committed.
  bool commit_if_due(std::chrono::steady_clock::time_point now);
  void commit();
  // Rows appended since the last commit.
  std::size_t pending_rows() const noexcept { return pending_rows_; }

  // Rows per multi-row estimate INSERT: a statement's fixed cost (opening and closing its cursors, ending it) shared
  // by this many rows halves the cost per row; more rows gain little (store_bench, docs/performance.md).
  static constexpr std::size_t kEstimateBatchRows = 32;

  // Reading, each in the order the rows were appended. A read-write Store also sees its own uncommitted rows.
  std::vector<Session> sessions() const;
  std::vector<Link> links(std::int64_t session) const;
  std::vector<Run> runs(std::int64_t session) const;
  std::vector<Event> events(std::int64_t session) const;
  // The readers that grow with a flight's length stream their rows through a callback, one row in memory at a time.
  void for_each_chunk(std::int64_t session, std::optional<std::int64_t> link,
                      const std::function<void(const Chunk&)>& visit) const;
  void for_each_sample(std::int64_t session, std::optional<std::int64_t> link,
                       const std::function<void(const protocol::Sample&)>& visit) const;
  void for_each_estimate(std::int64_t run, const std::function<void(const Estimate&)>& visit) const;
  void for_each_reference(std::int64_t session, const std::function<void(const ReferenceRow&)>& visit) const;

 private:
  struct PendingEstimate {
    std::int64_t run;
    Estimate estimate;
  };

  // Steps `statement` (bound, not yet stepped) inside the open batch; `what` names it in error messages.
  void execute(Statement& statement, std::string_view what);
  // execute() for one appended row, counted in the batch.
  void write(Statement& write, std::string_view what);
  // One more row in the open batch; commits when the batch is full.
  void count_pending_row();
  // Writes the estimates waiting in memory, in the order they were appended.
  void flush_estimates();
  // Inserts a row others will refer to, commits, and returns its id.
  std::int64_t insert_committed(Statement& insert, std::string_view what);
  [[noreturn]] void fail(const StoreError& error, std::string_view what);

  Database db_;
  Options options_;
  std::unique_ptr<WalCheckpointer> checkpointer_;  // after db_: stopped before the main connection closes
  std::size_t pending_rows_ = 0;
  std::optional<std::chrono::steady_clock::time_point> last_due_commit_;
  std::vector<PendingEstimate> pending_estimates_;
  std::set<std::pair<std::int64_t, std::int64_t>> accepted_run_links_;  // (run, link) pairs the schema took a row of

  Statement begin_{db_, "BEGIN IMMEDIATE"};
  Statement commit_{db_, "COMMIT"};
  Statement insert_session_{db_,
                            "INSERT INTO sessions (kind, source, started_wall_ns, config, software_version) "
                            "VALUES (?1, ?2, ?3, ?4, ?5)"};
  Statement end_session_{db_, "UPDATE sessions SET ended_wall_ns = ?2 WHERE id = ?1"};
  Statement insert_link_{db_, "INSERT INTO links (session_id, name, protocol, device) VALUES (?1, ?2, ?3, ?4)"};
  Statement insert_chunk_{db_,
                          "INSERT INTO chunks (session_id, link_id, direction, recv_mono_ns, recv_wall_ns, bytes) "
                          "VALUES (?1, ?2, ?3, ?4, ?5, ?6)"};
  Statement insert_sample_{db_,
                           "INSERT INTO samples (session_id, link_id, seq, device_time_us, recv_mono_ns, ax, ay, az, "
                           "gx, gy, gz, mx, my, mz, temperature_c, raw) "
                           "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16)"};
  Statement insert_event_{db_,
                          "INSERT INTO events (session_id, link_id, mono_ns, wall_ns, kind, count, detail) "
                          "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)"};
  Statement insert_run_{db_,
                        "INSERT INTO runs (session_id, kind, params, created_wall_ns, software_version) "
                        "VALUES (?1, ?2, ?3, ?4, ?5)"};
  static std::string insert_estimates_sql(std::size_t rows);
  Statement insert_estimate_{db_, insert_estimates_sql(1)};
  Statement insert_estimates_{db_, insert_estimates_sql(kEstimateBatchRows)};
  Statement insert_reference_{db_,
                              "INSERT INTO reference (session_id, t_ns, px, py, pz, qw, qx, qy, qz, vx, vy, vz) "
                              "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12)"};
};

}  // namespace imubridge::store
