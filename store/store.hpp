#pragma once
// The session store: one SQLite file keeping every raw byte chunk, decoded sample, event, pipeline run, estimate and
// reference pose of the sessions recorded into it. Writes are batched in one open transaction committed at least
// every commit_interval, so data is durable at most 200 ms (the default) after it was appended. A Store is used by
// one thread at a time. Layout and example queries: docs/storage.md.
#include <array>
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
#include "store/process_identity.hpp"
#include "store/records.hpp"
#include "store/sqlite.hpp"
#include "store/wal_checkpointer.hpp"

namespace imubridge::store {

// A session end_interrupted_sessions() ended.
struct InterruptedSession {
  std::int64_t session = 0;
  std::int64_t ended_wall_ns = 0;  // its last stored time
  ProcessIdentity writer{};
};

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

namespace detail {

// A row waiting for its burst, with what binding it needs: its parent (session or run) and values that must
// outlive the bind until the statement has stepped (a chunk's bytes, a sample's encoded raw counts).
struct WaitingChunk {
  std::int64_t session;
  Chunk chunk;
};
struct WaitingSample {
  std::int64_t session;
  protocol::Sample sample;
  std::array<std::uint8_t, 40> raw;  // Sample::raw as stored, little-endian int32s
};
struct WaitingEstimate {
  std::int64_t run;
  Estimate estimate;
};
}  // namespace detail

class Store {
 public:
  using Options = StoreOptions;

  // Opens or creates the database at `path`, migrating an older schema. Throws StoreError if the file is not an
  // imubridge database, was written by a newer imubridge, or cannot be opened.
  explicit Store(const std::filesystem::path& path, Options options = {});
  Store(const Store&) = delete;
  Store& operator=(const Store&) = delete;
  // Commits what is pending. A failure here can only be reported (report.hpp): call commit() first to handle it.
  ~Store();

  // Writing. Rows join the open batch; sessions, links and runs are committed at once since others refer to them.
  // A write that fails throws StoreError. A row the schema rejects (unknown session, link or run) is refused alone;
  // any other failure (disk full, I/O error) rolls back the batch, and the message says how many rows were lost.
  // The session's writer is this process (process_identity.hpp).
  std::int64_t begin_session(const SessionInfo& info);
  void end_session(std::int64_t session, std::int64_t ended_wall_ns);
  // Ends every open session whose writer has died (killed, crashed, or its machine lost power) as interrupted, at
  // its last stored time: the wall time of its last chunk or event (in the order they were appended), whichever is
  // later, or its start if it has neither. Each gets an `interrupted` event stamped with that time and the monotonic
  // time of the same row. A session whose writer still runs is left alone, as is one of schema version 1 (no writer
  // recorded). All in one transaction: two stores doing this at once end each session once. Returns those ended.
  std::vector<InterruptedSession> end_interrupted_sessions();
  std::int64_t add_link(std::int64_t session, std::string_view name, std::string_view protocol,
                        std::string_view device);
  // Chunks, samples and estimates come at the sample rate, so they wait in memory and reach SQLite in bursts, in
  // multi-row INSERTs of kRowsPerStatement: when kMaxWaitingRows of a table wait, or anything commits. A burst costs
  // far less per row than the same rows written one at a time between the daemon's waits for the next frame, its
  // caches cold (docs/performance.md). The first row of each (session, link), or (run, link), is written at once, so
  // an unknown session, link or run fails in that call. Waiting rows count as appended (pending_rows), this Store's
  // readers see them, and a commit writes them first: durability is the commit's, as for any row.
  void append_chunk(std::int64_t session, std::int64_t link, Direction direction, std::int64_t recv_mono_ns,
                    std::int64_t recv_wall_ns, std::span<const std::uint8_t> bytes);
  void append_sample(std::int64_t session, const protocol::Sample& sample);  // sample.link_id names the link
  void append_event(std::int64_t session, const Event& event);
  std::int64_t begin_run(std::int64_t session, const RunInfo& info);
  void append_estimate(std::int64_t run, const Estimate& estimate);
  void append_reference(std::int64_t session, const ReferenceRow& row);

  // Commits the batch if rows are pending and commit_interval has passed since this function's previous commit
  // (its first commit happens at once). Call it often, with the current time; returns whether it committed.
  bool commit_if_due(std::chrono::steady_clock::time_point now);
  void commit();
  // Rows appended since the last commit.
  std::size_t pending_rows() const noexcept { return pending_rows_; }

  // Rows per multi-row INSERT: a statement's fixed cost (opening and closing its cursors, ending it) shared by this
  // many rows halves the cost per row; more rows gain little (store_bench, docs/performance.md).
  static constexpr std::size_t kRowsPerStatement = 32;
  // A table's waiting rows are written when this many wait: at 1 kHz a link's 200 ms of rows wait for the commit;
  // faster sources (replay, many links) are written in bursts of this size, so memory stays bounded.
  static constexpr std::size_t kMaxWaitingRows = 8 * kRowsPerStatement;

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
  // for_each_sample's rows of one link with only what motion estimation reads: device and reception time,
  // accelerometer and gyro (seq, magnetometer, temperature and raw counts left at their defaults). Half the columns
  // to fetch from each of a flight's rows (identify's read, docs/performance.md).
  void for_each_motion_sample(std::int64_t session, std::int64_t link,
                              const std::function<void(const protocol::Sample&)>& visit) const;
  // Each link's first sample, in link order (links without samples left out): where the session's time starts.
  std::vector<protocol::Sample> first_samples(std::int64_t session) const;
  void for_each_estimate(std::int64_t run, const std::function<void(const Estimate&)>& visit) const;
  void for_each_reference(std::int64_t session, const std::function<void(const ReferenceRow&)>& visit) const;
  // Where another thread may open a read-only Store of its own that reads what this one reads (a Store serves one
  // thread at a time), to read two tables at once: this one's file when it is read-only; nullopt when it is
  // read-write, since its uncommitted rows are its own connection's.
  std::optional<std::filesystem::path> second_reader_path() const;

 private:
  // One table's waiting rows and its two INSERTs (one row, kRowsPerStatement rows).
  template <typename Row>
  struct Table {
    Table(const Database& db, std::string_view insert_into, std::size_t columns, std::string_view what_one,
          std::string_view what_many);
    Statement one, many;
    std::size_t columns;
    std::string what_one, what_many;  // "appending a sample", "appending samples"
    std::vector<Row> waiting;
    std::set<std::pair<std::int64_t, std::int64_t>> accepted;  // (parent, link) pairs the schema took a row of
  };

  // Steps `statement` (bound, not yet stepped) inside the open batch; `what` names it in error messages.
  void execute(Statement& statement, std::string_view what);
  // execute() for one appended row, counted in the batch.
  void write(Statement& write, std::string_view what);
  // One more row in the open batch; commits when the batch is full.
  void count_pending_row();
  // Adds a row to its table's waiting rows, or writes it at once if it is its (parent, link)'s first.
  template <typename Row>
  void append_waiting(Table<Row>& table, Row row);
  // Writes a table's waiting rows, in the order they were appended.
  template <typename Row>
  void flush(Table<Row>& table);
  void flush_all();
  bool anything_waiting() const noexcept;
  void drop_waiting() noexcept;
  // Inserts a row others will refer to, commits, and returns its id.
  std::int64_t insert_committed(Statement& insert, std::string_view what);
  [[noreturn]] void fail(const StoreError& error, std::string_view what);
  // One row of a query selecting kSelectSample's columns.
  protocol::Sample sample_from_row(const Statement& query, std::int64_t session) const;

  Database db_;
  Options options_;
  std::int64_t schema_version_ = 0;  // a read-only Store may read an older file
  std::optional<ProcessIdentity> writer_ = this_process();
  std::unique_ptr<WalCheckpointer> checkpointer_;  // after db_: stopped before the main connection closes
  std::size_t pending_rows_ = 0;
  std::optional<std::chrono::steady_clock::time_point> last_due_commit_;

  Statement begin_{db_, "BEGIN IMMEDIATE"};
  Statement commit_{db_, "COMMIT"};
  Statement end_session_{db_, "UPDATE sessions SET ended_wall_ns = ?2 WHERE id = ?1"};
  Statement insert_link_{db_, "INSERT INTO links (session_id, name, protocol, device) VALUES (?1, ?2, ?3, ?4)"};
  Table<detail::WaitingChunk> chunks_{db_, "chunks (session_id, link_id, direction, recv_mono_ns, recv_wall_ns, bytes)",
                                      6, "appending a chunk", "appending chunks"};
  Table<detail::WaitingSample> samples_{db_,
                                        "samples (session_id, link_id, seq, device_time_us, recv_mono_ns, ax, ay, "
                                        "az, gx, gy, gz, mx, my, mz, temperature_c, raw)",
                                        16, "appending a sample", "appending samples"};
  Statement insert_event_{db_,
                          "INSERT INTO events (session_id, link_id, mono_ns, wall_ns, kind, count, detail) "
                          "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)"};
  Statement insert_run_{db_,
                        "INSERT INTO runs (session_id, kind, params, created_wall_ns, software_version) "
                        "VALUES (?1, ?2, ?3, ?4, ?5)"};
  Table<detail::WaitingEstimate> estimates_{db_,
                                            "estimates (run_id, link_id, seq, t_s, fx, fy, vx, vy, var_vx, var_vy)", 10,
                                            "appending an estimate", "appending estimates"};
  Statement insert_reference_{db_,
                              "INSERT INTO reference (session_id, t_ns, px, py, pz, qw, qx, qy, qz, vx, vy, vz) "
                              "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12)"};
};

}  // namespace imubridge::store
