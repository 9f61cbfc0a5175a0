#include "store/store.hpp"

#include <sqlite3.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "store/report.hpp"
#include "store/schema.hpp"

namespace imubridge::store {
namespace {

using RawCounts = decltype(protocol::Sample::raw);
// Raw counts travel as one BLOB of little-endian int32s: one bind per sample instead of ten.
constexpr std::size_t kRawBytes = 4 * std::tuple_size_v<RawCounts>;

std::array<std::uint8_t, kRawBytes> encode_raw(const RawCounts& raw) {
  std::array<std::uint8_t, kRawBytes> bytes{};
  for (std::size_t i = 0; i < raw.size(); ++i) {
    const auto value = static_cast<std::uint32_t>(raw[i]);
    for (std::size_t b = 0; b < 4; ++b) bytes[4 * i + b] = static_cast<std::uint8_t>(value >> (8 * b));
  }
  return bytes;
}

RawCounts decode_raw(std::span<const std::uint8_t> bytes) {
  RawCounts raw{};
  for (std::size_t i = 0; i < raw.size(); ++i) {
    std::uint32_t value = 0;
    for (std::size_t b = 0; b < 4; ++b) value |= std::uint32_t{bytes[4 * i + b]} << (8 * b);
    raw[i] = static_cast<std::int32_t>(value);
  }
  return raw;
}

template <std::size_t N>
void bind_reals(Statement& statement, int first, const std::array<double, N>& values) {
  for (std::size_t i = 0; i < N; ++i) statement.bind_real(first + static_cast<int>(i), values[i]);
}

void bind_nulls(Statement& statement, int first, int count) {
  for (int i = 0; i < count; ++i) statement.bind_null(first + i);
}

template <std::size_t N>
std::array<double, N> column_reals(const Statement& row, int first) {
  std::array<double, N> values{};
  for (std::size_t i = 0; i < N; ++i) values[i] = row.column_real(first + static_cast<int>(i));
  return values;
}

// A group of columns (mag xyz, reference velocity) is absent when all are NULL; a lone NULL in it is a NaN.
template <std::size_t N>
std::optional<std::array<double, N>> column_optional_reals(const Statement& row, int first) {
  for (int i = 0; i < static_cast<int>(N); ++i) {
    if (!row.is_null(first + i)) return column_reals<N>(row, first);
  }
  return std::nullopt;
}

std::optional<std::int64_t> column_optional_int(const Statement& row, int column) {
  if (row.is_null(column)) return std::nullopt;
  return row.column_int(column);
}

// Sequence numbers are unsigned 64-bit, SQLite integers signed: the bits are stored as they are.
std::int64_t seq_to_column(std::uint64_t seq) { return static_cast<std::int64_t>(seq); }
constexpr std::string_view kSelectSample =
    "SELECT link_id, seq, device_time_us, recv_mono_ns, ax, ay, az, gx, gy, gz, mx, my, mz, temperature_c, raw "
    "FROM samples";

std::uint64_t seq_from_column(std::int64_t value) { return static_cast<std::uint64_t>(value); }

// SQLite stores a NaN as NULL, and a NULL reads back as the quiet NaN.
double as_stored(double value) { return std::isnan(value) ? std::numeric_limits<double>::quiet_NaN() : value; }

template <std::size_t N>
std::array<double, N> as_stored(std::array<double, N> values) {
  for (double& v : values) v = as_stored(v);
  return values;
}

// Each waiting row as reading it back from its table gives it, for this Store's readers.
Estimate as_stored(Estimate e) {
  for (double* v : {&e.t_s, &e.fx, &e.fy, &e.vx, &e.vy, &e.var_vx, &e.var_vy}) *v = as_stored(*v);
  return e;
}

protocol::Sample as_stored(protocol::Sample s) {
  s.accel = as_stored(s.accel);
  s.gyro = as_stored(s.gyro);
  // A group of columns that is all NULL reads back as absent (column_optional_reals).
  s.mag = as_stored(s.mag);
  if (!s.has_mag || std::all_of(s.mag.begin(), s.mag.end(), [](double v) { return std::isnan(v); })) {
    s.has_mag = false;
    s.mag = {};
  }
  if (!s.has_temperature || std::isnan(s.temperature_c)) {
    s.has_temperature = false;
    s.temperature_c = 0.0;
  }
  if (!s.has_raw) s.raw = {};
  return s;
}

// Each table's columns in its INSERT's order, from `first`.
void bind_row(Statement& statement, int first, const detail::WaitingChunk& row) {
  const Chunk& c = row.chunk;
  statement.bind_int(first, row.session)
      .bind_int(first + 1, c.link_id)
      .bind_text(first + 2, c.direction == Direction::tx ? "tx" : "rx")
      .bind_int(first + 3, c.recv_mono_ns)
      .bind_int(first + 4, c.recv_wall_ns)
      .bind_blob(first + 5, c.bytes);
}

void bind_row(Statement& statement, int first, const detail::WaitingSample& row) {
  const protocol::Sample& s = row.sample;
  statement.bind_int(first, row.session)
      .bind_int(first + 1, s.link_id)
      .bind_int(first + 2, seq_to_column(s.seq))
      .bind_int(first + 3, s.device_time_us)
      .bind_int(first + 4, s.recv_mono_ns);
  bind_reals(statement, first + 5, s.accel);
  bind_reals(statement, first + 8, s.gyro);
  if (s.has_mag) {
    bind_reals(statement, first + 11, s.mag);
  } else {
    bind_nulls(statement, first + 11, 3);
  }
  if (s.has_temperature) {
    statement.bind_real(first + 14, s.temperature_c);
  } else {
    statement.bind_null(first + 14);
  }
  if (s.has_raw) {
    statement.bind_blob(first + 15, row.raw);
  } else {
    statement.bind_null(first + 15);
  }
}

void bind_row(Statement& statement, int first, const detail::WaitingEstimate& row) {
  const Estimate& e = row.estimate;
  statement.bind_int(first, row.run).bind_int(first + 1, e.link_id).bind_int(first + 2, seq_to_column(e.seq));
  bind_reals(statement, first + 3, std::array{e.t_s, e.fx, e.fy, e.vx, e.vy, e.var_vx, e.var_vy});
}

// The (parent, link) pair whose first row is written at once.
std::pair<std::int64_t, std::int64_t> parent_and_link(const detail::WaitingChunk& row) {
  return {row.session, row.chunk.link_id};
}
std::pair<std::int64_t, std::int64_t> parent_and_link(const detail::WaitingSample& row) {
  return {row.session, row.sample.link_id};
}
std::pair<std::int64_t, std::int64_t> parent_and_link(const detail::WaitingEstimate& row) {
  return {row.run, row.estimate.link_id};
}

std::string insert_sql(std::string_view insert_into, std::size_t columns, std::size_t rows) {
  std::string row = "(?";
  for (std::size_t i = 1; i < columns; ++i) row += ", ?";
  row += ")";
  std::string sql = "INSERT INTO " + std::string(insert_into) + " VALUES " + row;
  for (std::size_t i = 1; i < rows; ++i) sql += ", " + row;
  return sql;
}

Statement& bind_optional_int(Statement& statement, int index, std::optional<std::int64_t> value) {
  return value ? statement.bind_int(index, *value) : statement.bind_null(index);
}

Database open_database(const std::filesystem::path& path, bool read_only) {
  Database db(path, read_only);
  open_schema(db, read_only);  // the version it leaves is read back by the Store
  db.exec("PRAGMA foreign_keys = ON");
  if (!read_only) {
    // WAL: readers (replay, export) never block the recorder. NORMAL: a commit costs no fsync; WAL still keeps the
    // file consistent through a crash, and an application crash loses nothing committed.
    Statement journal(db, "PRAGMA journal_mode = WAL");
    if (!journal.step() || journal.column_text(0) != "wal") throw StoreError(db.name() + ": cannot use WAL mode");
    db.exec("PRAGMA synchronous = NORMAL");
  }
  return db;
}

}  // namespace

Store::Store(const std::filesystem::path& path, Options options)
    : db_(open_database(path, options.read_only)), options_(options) {
  schema_version_ = db_.query_int("PRAGMA user_version");
  if (!options.read_only && options.background_checkpoint.count() > 0) {
    db_.exec("PRAGMA wal_autocheckpoint = 0");  // the checkpointer's job now
    checkpointer_ = std::make_unique<WalCheckpointer>(path, options.background_checkpoint);
  }
}

Store::~Store() {
  try {
    commit();
  } catch (const StoreError& e) {
    report(e.what());
  }
}

void Store::execute(Statement& statement, std::string_view what) {
  try {
    if (!db_.in_transaction()) begin_.step();
    statement.step();
  } catch (const StoreError& e) {
    fail(e, what);
  }
}

void Store::write(Statement& write, std::string_view what) {
  execute(write, what);
  count_pending_row();
}

void Store::count_pending_row() {
  ++pending_rows_;
  if (pending_rows_ >= options_.max_batch_rows) commit();
}

std::int64_t Store::insert_committed(Statement& insert, std::string_view what) {
  write(insert, what);
  const std::int64_t id = db_.last_insert_id();
  commit();
  return id;
}

void Store::fail(const StoreError& error, std::string_view what) {
  std::string message = std::string(error.what()) + " (" + std::string(what) + ")";
  // A constraint failure undoes only the offending statement: the batch is still good and stays open.
  if (error.sqlite_code() == SQLITE_CONSTRAINT && db_.in_transaction()) throw StoreError(message, error.sqlite_code());
  db_.rollback();
  drop_waiting();  // they were part of the batch
  if (pending_rows_ > 0) {
    message += "; rolled back the " + std::to_string(pending_rows_) +
               " rows appended since the last commit, earlier data is intact";
  }
  pending_rows_ = 0;
  throw StoreError(message, error.sqlite_code());
}

bool Store::commit_if_due(std::chrono::steady_clock::time_point now) {
  // Not pending_rows_: a rejected first row leaves an empty batch open.
  if (!db_.in_transaction() && !anything_waiting()) return false;
  if (last_due_commit_ && now - *last_due_commit_ < options_.commit_interval) return false;
  commit();
  last_due_commit_ = now;
  return true;
}

void Store::commit() {
  flush_all();
  if (!db_.in_transaction()) return;
  try {
    commit_.step();
  } catch (const StoreError& e) {
    fail(e, "committing");
  }
  pending_rows_ = 0;
}

std::int64_t Store::begin_session(const SessionInfo& info) {
  // Prepared here rather than with the other statements: a read-only Store of a version 1 file has no writer columns.
  Statement insert(db_,
                   "INSERT INTO sessions (kind, source, started_wall_ns, config, software_version, writer_pid, "
                   "writer_boot_id, writer_start_ticks) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)");
  insert.bind_text(1, info.kind)
      .bind_text(2, info.source)
      .bind_int(3, info.started_wall_ns)
      .bind_text(4, info.config)
      .bind_text(5, info.software_version);
  if (writer_) {
    insert.bind_int(6, writer_->pid).bind_text(7, writer_->boot_id).bind_int(8, writer_->start_ticks);
  } else {
    bind_nulls(insert, 6, 3);
  }
  return insert_committed(insert, "starting a session");
}

std::vector<InterruptedSession> Store::end_interrupted_sessions() {
  commit();
  std::vector<InterruptedSession> ended;
  try {
    // BEGIN IMMEDIATE: another process doing the same waits, then finds these sessions ended.
    begin_.step();
    std::vector<InterruptedSession> open;
    Statement query(db_,
                    "SELECT id, started_wall_ns, writer_pid, writer_boot_id, writer_start_ticks FROM sessions "
                    "WHERE ended_wall_ns IS NULL AND writer_pid IS NOT NULL ORDER BY id");
    while (query.step()) {
      open.push_back(
          {.session = query.column_int(0),
           .ended_wall_ns = query.column_int(1),
           .writer = {
               .pid = query.column_int(2), .boot_id = query.column_text(3), .start_ticks = query.column_int(4)}});
    }
    for (InterruptedSession& s : open) {
      if (is_running(s.writer)) continue;
      std::int64_t last_mono_ns = 0;
      for (const char* last_row :
           {"SELECT recv_mono_ns, recv_wall_ns FROM chunks WHERE session_id = ?1 "
            "ORDER BY id DESC LIMIT 1",
            "SELECT mono_ns, wall_ns FROM events WHERE session_id = ?1 ORDER BY id DESC LIMIT 1"}) {
        Statement last(db_, last_row);
        last.bind_int(1, s.session);
        if (last.step() && last.column_int(1) >= s.ended_wall_ns) {
          last_mono_ns = last.column_int(0);
          s.ended_wall_ns = last.column_int(1);
        }
      }
      Statement mark(db_, "UPDATE sessions SET ended_wall_ns = ?2, interrupted = 1 WHERE id = ?1");
      mark.bind_int(1, s.session).bind_int(2, s.ended_wall_ns);
      mark.step();
      const std::string detail = "its writer, process " + std::to_string(s.writer.pid) +
                                 ", ended without ending it; ended at its last stored time by process " +
                                 (writer_ ? std::to_string(writer_->pid) : std::string("?"));
      insert_event_.bind_int(1, s.session)
          .bind_null(2)
          .bind_int(3, last_mono_ns)
          .bind_int(4, s.ended_wall_ns)
          .bind_text(5, "interrupted")
          .bind_int(6, 1)
          .bind_text(7, detail);
      insert_event_.step();
      ended.push_back(s);
    }
    commit_.step();
  } catch (const StoreError& e) {
    fail(e, "ending interrupted sessions");
  }
  return ended;
}

void Store::end_session(std::int64_t session, std::int64_t ended_wall_ns) {
  flush_all();  // so that changes() below counts the UPDATE, not a burst of waiting rows
  end_session_.bind_int(1, session).bind_int(2, ended_wall_ns);
  write(end_session_, "ending a session");
  commit();  // leaves changes() alone: it counts the UPDATE's rows
  if (db_.changes() == 0) throw StoreError(db_.name() + ": no session " + std::to_string(session) + " to end");
}

std::int64_t Store::add_link(std::int64_t session, std::string_view name, std::string_view protocol,
                             std::string_view device) {
  insert_link_.bind_int(1, session).bind_text(2, name).bind_text(3, protocol).bind_text(4, device);
  return insert_committed(insert_link_, "adding a link");
}

void Store::append_chunk(std::int64_t session, std::int64_t link, Direction direction, std::int64_t recv_mono_ns,
                         std::int64_t recv_wall_ns, std::span<const std::uint8_t> bytes) {
  append_waiting(chunks_, detail::WaitingChunk{.session = session,
                                               .chunk = {.link_id = link,
                                                         .direction = direction,
                                                         .recv_mono_ns = recv_mono_ns,
                                                         .recv_wall_ns = recv_wall_ns,
                                                         .bytes = {bytes.begin(), bytes.end()}}});
}

void Store::append_sample(std::int64_t session, const protocol::Sample& sample) {
  static_assert(std::tuple_size_v<decltype(detail::WaitingSample::raw)> == kRawBytes);
  append_waiting(samples_, detail::WaitingSample{.session = session, .sample = sample, .raw = encode_raw(sample.raw)});
}

void Store::append_event(std::int64_t session, const Event& event) {
  insert_event_.bind_int(1, session);
  bind_optional_int(insert_event_, 2, event.link_id)
      .bind_int(3, event.mono_ns)
      .bind_int(4, event.wall_ns)
      .bind_text(5, event.kind)
      .bind_int(6, event.count)
      .bind_text(7, event.detail);
  write(insert_event_, "appending an event");
}

std::int64_t Store::begin_run(std::int64_t session, const RunInfo& info) {
  insert_run_.bind_int(1, session)
      .bind_text(2, info.kind)
      .bind_text(3, info.params_json)
      .bind_int(4, info.created_wall_ns)
      .bind_text(5, info.software_version);
  return insert_committed(insert_run_, "starting a run");
}

void Store::append_estimate(std::int64_t run, const Estimate& e) {
  append_waiting(estimates_, detail::WaitingEstimate{.run = run, .estimate = e});
}

template <typename Row>
Store::Table<Row>::Table(const Database& db, std::string_view insert_into, std::size_t columns,
                         std::string_view what_one, std::string_view what_many)
    : one(db, insert_sql(insert_into, columns, 1)),
      many(db, insert_sql(insert_into, columns, kRowsPerStatement)),
      columns(columns),
      what_one(what_one),
      what_many(what_many) {}

template <typename Row>
void Store::append_waiting(Table<Row>& table, Row row) {
  const auto key = parent_and_link(row);
  if (!table.accepted.contains(key)) {
    flush(table);  // the rows appended before it go first
    bind_row(table.one, 1, row);
    write(table.one, table.what_one);
    table.accepted.insert(key);  // nothing deletes sessions, runs or links: later rows will be accepted too
    return;
  }
  table.waiting.push_back(std::move(row));
  count_pending_row();  // may commit, which writes every waiting row
  if (table.waiting.size() >= kMaxWaitingRows) flush(table);
}

template <typename Row>
void Store::flush(Table<Row>& table) {
  std::optional<StoreError> refused;  // the first row the schema refused: thrown once the others are in
  std::size_t written = 0;
  auto& rows = table.waiting;
  // Any failure but a refused row rolls the batch back, which drops these rows too (fail()) and ends the loops.
  for (; rows.size() - written >= kRowsPerStatement; written += kRowsPerStatement) {
    for (std::size_t i = 0; i < kRowsPerStatement; ++i) {
      bind_row(table.many, static_cast<int>(1 + i * table.columns), rows[written + i]);
    }
    try {
      execute(table.many, table.what_many);
    } catch (const StoreError& error) {
      // Only a parent or link deleted by another program gets here; row by row below, only its rows are refused.
      if (error.sqlite_code() != SQLITE_CONSTRAINT) throw;
      break;
    }
  }
  for (; written < rows.size(); ++written) {
    bind_row(table.one, 1, rows[written]);
    try {
      execute(table.one, table.what_one);
    } catch (const StoreError& error) {
      if (error.sqlite_code() != SQLITE_CONSTRAINT) throw;
      --pending_rows_;
      if (!refused) refused = error;
    }
  }
  rows.clear();
  if (refused) throw *refused;
}

void Store::flush_all() {
  std::optional<StoreError> refused;  // every table is written before a refused row is reported
  const auto flush_keeping_refusal = [&](auto& table) {
    try {
      flush(table);
    } catch (const StoreError& error) {
      if (error.sqlite_code() != SQLITE_CONSTRAINT) throw;
      if (!refused) refused = error;
    }
  };
  flush_keeping_refusal(chunks_);
  flush_keeping_refusal(samples_);
  flush_keeping_refusal(estimates_);
  if (refused) throw *refused;
}

bool Store::anything_waiting() const noexcept {
  return !chunks_.waiting.empty() || !samples_.waiting.empty() || !estimates_.waiting.empty();
}

void Store::drop_waiting() noexcept {
  chunks_.waiting.clear();
  samples_.waiting.clear();
  estimates_.waiting.clear();
}

void Store::append_reference(std::int64_t session, const ReferenceRow& row) {
  insert_reference_.bind_int(1, session).bind_int(2, row.t_ns);
  bind_reals(insert_reference_, 3, row.position);
  bind_reals(insert_reference_, 6, row.quat_wxyz);
  if (row.velocity) {
    bind_reals(insert_reference_, 10, *row.velocity);
  } else {
    bind_nulls(insert_reference_, 10, 3);
  }
  write(insert_reference_, "appending a reference row");
}

std::vector<Session> Store::sessions() const {
  Statement query(db_, schema_version_ >= 2 ? "SELECT id, kind, source, config, started_wall_ns, software_version, "
                                              "ended_wall_ns, interrupted, writer_pid, writer_boot_id, "
                                              "writer_start_ticks FROM sessions ORDER BY id"
                                            : "SELECT id, kind, source, config, started_wall_ns, software_version, "
                                              "ended_wall_ns, 0, NULL, NULL, NULL FROM sessions ORDER BY id");
  std::vector<Session> sessions;
  while (query.step()) {
    Session& s = sessions.emplace_back(Session{.id = query.column_int(0),
                                               .info = {.kind = query.column_text(1),
                                                        .source = query.column_text(2),
                                                        .config = query.column_text(3),
                                                        .started_wall_ns = query.column_int(4),
                                                        .software_version = query.column_text(5)},
                                               .ended_wall_ns = column_optional_int(query, 6),
                                               .interrupted = query.column_int(7) != 0});
    if (!query.is_null(8)) {
      s.writer = ProcessIdentity{
          .pid = query.column_int(8), .boot_id = query.column_text(9), .start_ticks = query.column_int(10)};
    }
  }
  return sessions;
}

std::vector<Link> Store::links(std::int64_t session) const {
  Statement query(db_, "SELECT id, name, protocol, device FROM links WHERE session_id = ?1 ORDER BY id");
  query.bind_int(1, session);
  std::vector<Link> links;
  while (query.step()) {
    links.push_back({.id = query.column_int(0),
                     .session_id = session,
                     .name = query.column_text(1),
                     .protocol = query.column_text(2),
                     .device = query.column_text(3)});
  }
  return links;
}

std::vector<Run> Store::runs(std::int64_t session) const {
  Statement query(db_,
                  "SELECT id, kind, params, created_wall_ns, software_version FROM runs "
                  "WHERE session_id = ?1 ORDER BY id");
  query.bind_int(1, session);
  std::vector<Run> runs;
  while (query.step()) {
    runs.push_back({.id = query.column_int(0),
                    .session_id = session,
                    .info = {.kind = query.column_text(1),
                             .params_json = query.column_text(2),
                             .created_wall_ns = query.column_int(3),
                             .software_version = query.column_text(4)}});
  }
  return runs;
}

std::vector<Event> Store::events(std::int64_t session) const {
  Statement query(db_,
                  "SELECT link_id, mono_ns, wall_ns, kind, count, detail FROM events "
                  "WHERE session_id = ?1 ORDER BY id");
  query.bind_int(1, session);
  std::vector<Event> events;
  while (query.step()) {
    events.push_back({.link_id = column_optional_int(query, 0),
                      .mono_ns = query.column_int(1),
                      .wall_ns = query.column_int(2),
                      .kind = query.column_text(3),
                      .count = query.column_int(4),
                      .detail = query.column_text(5)});
  }
  return events;
}

void Store::for_each_chunk(std::int64_t session, std::optional<std::int64_t> link,
                           const std::function<void(const Chunk&)>& visit) const {
  Statement query(db_,
                  "SELECT link_id, direction, recv_mono_ns, recv_wall_ns, bytes FROM chunks "
                  "WHERE session_id = ?1 AND (?2 IS NULL OR link_id = ?2) ORDER BY id");
  query.bind_int(1, session);
  bind_optional_int(query, 2, link);
  Chunk chunk;  // one buffer for the whole session
  while (query.step()) {
    const auto bytes = query.column_blob(4);
    chunk.link_id = query.column_int(0);
    chunk.direction = query.column_text(1) == "tx" ? Direction::tx : Direction::rx;
    chunk.recv_mono_ns = query.column_int(2);
    chunk.recv_wall_ns = query.column_int(3);
    chunk.bytes.assign(bytes.begin(), bytes.end());
    visit(chunk);
  }
  for (const auto& [waiting_session, c] : chunks_.waiting) {  // appended after every row above
    if (waiting_session == session && (!link || c.link_id == *link)) visit(c);
  }
}

void Store::for_each_sample(std::int64_t session, std::optional<std::int64_t> link,
                            const std::function<void(const protocol::Sample&)>& visit) const {
  Statement query(db_,
                  std::string(kSelectSample) + " WHERE session_id = ?1 AND (?2 IS NULL OR link_id = ?2) ORDER BY id");
  query.bind_int(1, session);
  bind_optional_int(query, 2, link);
  while (query.step()) visit(sample_from_row(query, session));
  for (const auto& w : samples_.waiting) {  // appended after every row above
    if (w.session == session && (!link || w.sample.link_id == *link)) visit(as_stored(w.sample));
  }
}

std::optional<std::filesystem::path> Store::second_reader_path() const {
  if (!options_.read_only) return std::nullopt;
  return std::filesystem::path(db_.name());
}

void Store::for_each_motion_sample(std::int64_t session, std::int64_t link,
                                   const std::function<void(const protocol::Sample&)>& visit) const {
  Statement query(db_,
                  "SELECT device_time_us, recv_mono_ns, ax, ay, az, gx, gy, gz FROM samples "
                  "WHERE session_id = ?1 AND link_id = ?2 ORDER BY id");
  query.bind_int(1, session);
  query.bind_int(2, link);
  protocol::Sample sample;
  sample.link_id = link;
  while (query.step()) {
    sample.device_time_us = query.column_int(0);
    sample.recv_mono_ns = query.column_int(1);
    sample.accel = column_reals<3>(query, 2);
    sample.gyro = column_reals<3>(query, 5);
    visit(sample);
  }
  for (const auto& w : samples_.waiting) {  // appended after every row above
    if (w.session != session || w.sample.link_id != link) continue;
    const protocol::Sample stored = as_stored(w.sample);
    sample.device_time_us = stored.device_time_us;
    sample.recv_mono_ns = stored.recv_mono_ns;
    sample.accel = stored.accel;
    sample.gyro = stored.gyro;
    visit(sample);
  }
}

std::vector<protocol::Sample> Store::first_samples(std::int64_t session) const {
  std::vector<protocol::Sample> firsts;
  for (const Link& link : links(session)) {
    // The index on session_id keeps each session's rows in id order: the first match is the link's first sample.
    Statement query(db_, std::string(kSelectSample) + " WHERE session_id = ?1 AND link_id = ?2 ORDER BY id LIMIT 1");
    query.bind_int(1, session);
    query.bind_int(2, link.id);
    if (query.step()) {
      firsts.push_back(sample_from_row(query, session));
      continue;
    }
    for (const auto& w : samples_.waiting) {  // none committed yet
      if (w.session == session && w.sample.link_id == link.id) {
        firsts.push_back(as_stored(w.sample));
        break;
      }
    }
  }
  return firsts;
}

protocol::Sample Store::sample_from_row(const Statement& query, std::int64_t session) const {
  protocol::Sample sample;
  sample.link_id = query.column_int(0);
  sample.seq = seq_from_column(query.column_int(1));
  sample.device_time_us = query.column_int(2);
  sample.recv_mono_ns = query.column_int(3);
  sample.accel = column_reals<3>(query, 4);
  sample.gyro = column_reals<3>(query, 7);
  if (const auto mag = column_optional_reals<3>(query, 10)) {
    sample.mag = *mag;
    sample.has_mag = true;
  }
  if (const auto temperature = column_optional_reals<1>(query, 13)) {
    sample.temperature_c = (*temperature)[0];
    sample.has_temperature = true;
  }
  if (!query.is_null(14)) {
    const auto raw = query.column_blob(14);
    if (raw.size() != kRawBytes) {
      throw StoreError(db_.name() + ": a sample of session " + std::to_string(session) + " has " +
                       std::to_string(raw.size()) + " bytes of raw counts, not " + std::to_string(kRawBytes));
    }
    sample.raw = decode_raw(raw);
    sample.has_raw = true;
  }
  return sample;
}

void Store::for_each_estimate(std::int64_t run, const std::function<void(const Estimate&)>& visit) const {
  Statement query(db_,
                  "SELECT link_id, seq, t_s, fx, fy, vx, vy, var_vx, var_vy FROM estimates "
                  "WHERE run_id = ?1 ORDER BY id");
  query.bind_int(1, run);
  while (query.step()) {
    const auto [t_s, fx, fy, vx, vy, var_vx, var_vy] = column_reals<7>(query, 2);
    visit({.link_id = query.column_int(0),
           .seq = seq_from_column(query.column_int(1)),
           .t_s = t_s,
           .fx = fx,
           .fy = fy,
           .vx = vx,
           .vy = vy,
           .var_vx = var_vx,
           .var_vy = var_vy});
  }
  for (const auto& [waiting_run, e] : estimates_.waiting) {  // appended after every row above
    if (waiting_run == run) visit(as_stored(e));
  }
}

void Store::for_each_reference(std::int64_t session, const std::function<void(const ReferenceRow&)>& visit) const {
  Statement query(db_,
                  "SELECT t_ns, px, py, pz, qw, qx, qy, qz, vx, vy, vz FROM reference "
                  "WHERE session_id = ?1 ORDER BY id");
  query.bind_int(1, session);
  while (query.step()) {
    visit({.t_ns = query.column_int(0),
           .position = column_reals<3>(query, 1),
           .quat_wxyz = column_reals<4>(query, 4),
           .velocity = column_optional_reals<3>(query, 8)});
  }
}

}  // namespace imubridge::store
