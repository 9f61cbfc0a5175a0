#include "archive/sync.hpp"

#include <unistd.h>

#include <array>
#include <climits>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "archive/archive_schema.hpp"
#include "archive/copy_format.hpp"
#include "store/schema.hpp"
#include "store/sqlite.hpp"

namespace imubridge::archive {
namespace {

// A batch's COPY data stops growing here, whatever its row count: chunks carry up to kilobytes each.
constexpr std::size_t kMaxBatchBytes = 16u << 20;

enum class Kind { integer, real, text, blob };
struct Column {
  std::string_view name;
  Kind kind;
};

// A table copied row for row. Its rows belong to a session (or, for estimates, to a run of it); `columns` are
// those after id that both sides have, station and session_id aside (which the archive adds and keys on).
struct TableCopy {
  std::string_view name;
  std::string_view parent;  // the store's column the rows are read by: session_id or run_id
  std::vector<Column> columns;
};

const TableCopy kLinks{"links", "session_id", {{"name", Kind::text}, {"protocol", Kind::text}, {"device", Kind::text}}};
const TableCopy kRuns{"runs",
                      "session_id",
                      {{"kind", Kind::text},
                       {"params", Kind::text},
                       {"created_wall_ns", Kind::integer},
                       {"software_version", Kind::text}}};
const TableCopy kSamples{"samples",
                         "session_id",
                         {{"link_id", Kind::integer},
                          {"seq", Kind::integer},
                          {"device_time_us", Kind::integer},
                          {"recv_mono_ns", Kind::integer},
                          {"ax", Kind::real},
                          {"ay", Kind::real},
                          {"az", Kind::real},
                          {"gx", Kind::real},
                          {"gy", Kind::real},
                          {"gz", Kind::real},
                          {"mx", Kind::real},
                          {"my", Kind::real},
                          {"mz", Kind::real},
                          {"temperature_c", Kind::real},
                          {"raw", Kind::blob}}};
const TableCopy kEvents{"events",
                        "session_id",
                        {{"link_id", Kind::integer},
                         {"mono_ns", Kind::integer},
                         {"wall_ns", Kind::integer},
                         {"kind", Kind::text},
                         {"count", Kind::integer},
                         {"detail", Kind::text}}};
const TableCopy kReference{"reference",
                           "session_id",
                           {{"t_ns", Kind::integer},
                            {"px", Kind::real},
                            {"py", Kind::real},
                            {"pz", Kind::real},
                            {"qw", Kind::real},
                            {"qx", Kind::real},
                            {"qy", Kind::real},
                            {"qz", Kind::real},
                            {"vx", Kind::real},
                            {"vy", Kind::real},
                            {"vz", Kind::real}}};
const TableCopy kChunks{"chunks",
                        "session_id",
                        {{"link_id", Kind::integer},
                         {"direction", Kind::text},
                         {"recv_mono_ns", Kind::integer},
                         {"recv_wall_ns", Kind::integer},
                         {"bytes", Kind::blob}}};
const TableCopy kEstimates{"estimates",
                           "run_id",
                           {{"run_id", Kind::integer},
                            {"link_id", Kind::integer},
                            {"seq", Kind::integer},
                            {"t_s", Kind::real},
                            {"fx", Kind::real},
                            {"fy", Kind::real},
                            {"vx", Kind::real},
                            {"vy", Kind::real},
                            {"var_vx", Kind::real},
                            {"var_vy", Kind::real}}};

std::string column_list(const TableCopy& table) {
  std::string list;
  for (const Column& c : table.columns) list += ", " + std::string(c.name);
  return list;
}

// A session as the store has it.
struct LocalSession {
  std::int64_t id = 0;
  std::string kind, source, config, software_version;
  std::int64_t started_wall_ns = 0;
  std::optional<std::int64_t> ended_wall_ns, writer_pid, writer_start_ticks;
  std::optional<std::string> writer_boot_id;
  std::int64_t interrupted = 0;
};

std::optional<std::string> optional_text(const store::Statement& row, int column) {
  if (row.is_null(column)) return std::nullopt;
  return row.column_text(column);
}
std::optional<std::int64_t> optional_int(const store::Statement& row, int column) {
  if (row.is_null(column)) return std::nullopt;
  return row.column_int(column);
}
std::optional<std::string> as_param(std::optional<std::int64_t> value) {
  if (!value) return std::nullopt;
  return std::to_string(*value);
}

std::vector<LocalSession> local_sessions(const store::Database& db, std::int64_t schema_version,
                                         std::optional<std::int64_t> only) {
  // Files of schema 1 have no writer columns: their sessions have no writer (docs/storage.md).
  const std::string writer =
      schema_version >= 2 ? "writer_pid, writer_boot_id, writer_start_ticks, interrupted" : "NULL, NULL, NULL, 0";
  store::Statement query(db, "SELECT id, kind, source, started_wall_ns, ended_wall_ns, config, software_version, " +
                                 writer + " FROM sessions WHERE ?1 IS NULL OR id = ?1 ORDER BY id");
  if (only) {
    query.bind_int(1, *only);
  } else {
    query.bind_null(1);
  }
  std::vector<LocalSession> sessions;
  while (query.step()) {
    sessions.push_back({.id = query.column_int(0),
                        .kind = query.column_text(1),
                        .source = query.column_text(2),
                        .config = query.column_text(5),
                        .software_version = query.column_text(6),
                        .started_wall_ns = query.column_int(3),
                        .ended_wall_ns = optional_int(query, 4),
                        .writer_pid = optional_int(query, 7),
                        .writer_start_ticks = optional_int(query, 9),
                        .writer_boot_id = optional_text(query, 8),
                        .interrupted = query.column_int(10)});
  }
  if (only && sessions.empty()) {
    throw store::StoreError(db.name() + " has no session " + std::to_string(*only));
  }
  return sessions;
}

std::vector<std::int64_t> local_runs(const store::Database& db, std::int64_t session) {
  store::Statement query(db, "SELECT id FROM runs WHERE session_id = ?1 ORDER BY id");
  query.bind_int(1, session);
  std::vector<std::int64_t> runs;
  while (query.step()) runs.push_back(query.column_int(0));
  return runs;
}

// A session's row as the archive has it.
struct ArchivedSession {
  std::string kind;
  std::int64_t started_wall_ns = 0;
  std::optional<std::string> synced_through;
};

// Where the store's session stood when a pass began: its ending and each table's largest id (chunks: "-" when not
// copied). A pass that copied the session through writes it to the archive's row; a later pass that finds the same
// skips the session without a query, so a rerun over a store of hundreds of ended sessions costs one query, not
// seven per session (a replay adding a run to an old session changes it, and the run is copied).
std::string local_position(const store::Database& db, const LocalSession& s, const std::vector<std::int64_t>& runs,
                           bool chunks) {
  const auto largest_id = [&](std::string_view table, std::string_view parent, std::int64_t of) {
    store::Statement query(
        db, "SELECT coalesce(max(id), 0) FROM " + std::string(table) + " WHERE " + std::string(parent) + " = ?1");
    query.bind_int(1, of);
    return std::to_string(query.step() ? query.column_int(0) : 0);  // an aggregate: one row
  };
  std::string position = "ended=" + (s.ended_wall_ns ? std::to_string(*s.ended_wall_ns) : std::string("-")) +
                         " interrupted=" + std::to_string(s.interrupted);
  for (std::string_view table : {"links", "runs", "events", "reference", "samples"}) {
    position += " " + std::string(table) + "=" + largest_id(table, "session_id", s.id);
  }
  for (std::int64_t run : runs) {
    position += " estimates." + std::to_string(run) + "=" + largest_id("estimates", "run_id", run);
  }
  position += " chunks=" + (chunks ? largest_id("chunks", "session_id", s.id) : std::string("-"));
  return position;
}

class SessionSync {
 public:
  SessionSync(const store::Database& db, PgConnection& pg, const SyncOptions& options, SyncCounts& counts,
              const std::function<void(const SyncProgress&)>& progress)
      : db_(db), pg_(pg), options_(options), counts_(counts), progress_(progress) {
    const PgResult rows = pg_.query("SELECT id, kind, started_wall_ns, synced_through FROM sessions WHERE station = $1",
                                    {options_.station});
    for (int i = 0; i < rows.rows(); ++i) {
      archived_[rows.integer(i, 0)] = {
          .kind = rows.text(i, 1),
          .started_wall_ns = rows.integer(i, 2),
          .synced_through = rows.is_null(i, 3) ? std::nullopt : std::optional(rows.text(i, 3))};
    }
  }

  // False when asked to stop before the session was through.
  bool sync(const LocalSession& s) {
    const std::vector<std::int64_t> runs = local_runs(db_, s.id);
    const std::string position = local_position(db_, s, runs, options_.chunks);
    if (!add_session(s, position)) return true;  // nothing new since the last pass through it
    // Parents before the rows that name them; the ending last, once every row it covers is in.
    for (const auto& [table, count] :
         std::array<std::pair<const TableCopy*, std::int64_t*>, 5>{{{&kLinks, &counts_.links},
                                                                    {&kRuns, &counts_.runs},
                                                                    {&kEvents, &counts_.events},
                                                                    {&kReference, &counts_.reference},
                                                                    {&kSamples, &counts_.samples}}}) {
      if (!copy(*table, s.id, std::nullopt, *count)) return false;
    }
    for (std::int64_t run : runs) {
      if (!copy(kEstimates, s.id, run, counts_.estimates)) return false;
    }
    if (options_.chunks && !copy(kChunks, s.id, std::nullopt, counts_.chunks)) return false;
    end_session(s);
    pg_.query("UPDATE sessions SET synced_through = $3 WHERE station = $1 AND id = $2",
              {options_.station, std::to_string(s.id), position});
    return true;
  }

 private:
  // The session's row: created on its first sync (open, whatever it is by now); one of the same (station, id) that
  // is not this session means two stores share a station name, and mixing their rows would corrupt both. False
  // when the archive has the session through `position` already.
  bool add_session(const LocalSession& s, const std::string& position) {
    if (const auto found = archived_.find(s.id); found != archived_.end()) {
      const ArchivedSession& a = found->second;
      if (a.kind != s.kind || a.started_wall_ns != s.started_wall_ns) {
        throw ArchiveError(pg_.name() + ": station '" + options_.station + "' session " + std::to_string(s.id) +
                           " in the archive is another session (" + a.kind + ", started_wall_ns " +
                           std::to_string(a.started_wall_ns) + ") than this store's (" + s.kind + ", started_wall_ns " +
                           std::to_string(s.started_wall_ns) +
                           "): each store file needs its own station name (--station)");
      }
      return a.synced_through != position;
    }
    pg_.query(
        "INSERT INTO sessions (station, id, kind, source, started_wall_ns, config, software_version, writer_pid, "
        "writer_boot_id, writer_start_ticks) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10)",
        {options_.station, std::to_string(s.id), s.kind, s.source, std::to_string(s.started_wall_ns), s.config,
         s.software_version, as_param(s.writer_pid), s.writer_boot_id, as_param(s.writer_start_ticks)});
    ++counts_.sessions_added;
    return true;
  }

  // The ending read before any row was copied: every row of an ended session was committed before it ended.
  void end_session(const LocalSession& s) {
    if (!s.ended_wall_ns) return;
    const PgResult ended = pg_.query(
        "UPDATE sessions SET ended_wall_ns = $3, interrupted = $4 WHERE station = $1 AND id = $2 "
        "AND (ended_wall_ns IS DISTINCT FROM $3::bigint OR interrupted <> $4::integer) RETURNING id",
        {options_.station, std::to_string(s.id), std::to_string(*s.ended_wall_ns), std::to_string(s.interrupted)});
    counts_.sessions_ended += ended.rows();
  }

  std::int64_t archived_up_to(const TableCopy& table, std::int64_t session, std::optional<std::int64_t> run) {
    std::string sql = "SELECT max(id) FROM " + std::string(table.name) + " WHERE station = $1 AND session_id = $2";
    std::vector<std::optional<std::string>> params{options_.station, std::to_string(session)};
    if (run) {
      sql += " AND run_id = $3";
      params.push_back(std::to_string(*run));
    }
    const PgResult up_to = pg_.query(sql, params);
    return up_to.is_null(0, 0) ? 0 : up_to.integer(0, 0);
  }

  // Copies the rows of `session` (or of its `run`) that the archive lacks, batch by batch.
  bool copy(const TableCopy& table, std::int64_t session, std::optional<std::int64_t> run, std::int64_t& count) {
    std::int64_t after = archived_up_to(table, session, run);
    const std::string read_sql = "SELECT id" + column_list(table) + " FROM " + std::string(table.name) + " WHERE " +
                                 std::string(table.parent) + " = ?1 AND id > ?2 ORDER BY id LIMIT ?3";
    const std::string copy_sql = "COPY " + std::string(table.name) + " (station, session_id, id" + column_list(table) +
                                 ") FROM STDIN (FORMAT binary)";
    CopyRows rows;
    while (true) {
      if (options_.stop_requested && options_.stop_requested()) return false;
      rows.clear();
      {
        // One statement, one read snapshot of the store: rows committed by now, never a half-written batch. Made
        // anew each batch and gone before the batch is sent, so no read of ours holds back the store's
        // write-ahead log while PostgreSQL works.
        store::Statement read(db_, read_sql);
        read.bind_int(1, run ? *run : session)
            .bind_int(2, after)
            .bind_int(3, static_cast<std::int64_t>(options_.batch_rows));
        while (read.step()) {
          after = read.column_int(0);
          rows.text(options_.station).integer(session).integer(after);
          for (std::size_t i = 0; i < table.columns.size(); ++i) {
            add_value(rows, read, static_cast<int>(i) + 1, table.columns[i].kind);
          }
          rows.end_row();
          if (rows.size() >= kMaxBatchBytes) break;
        }
      }
      if (rows.rows() == 0) return true;
      pg_.transaction([&] { pg_.copy_in(copy_sql, rows.finish()); });
      count += static_cast<std::int64_t>(rows.rows());
      if (progress_)
        progress_({.session = session, .table = table.name, .rows = static_cast<std::int64_t>(rows.rows())});
    }
  }

  static void add_value(CopyRows& rows, const store::Statement& row, int column, Kind kind) {
    if (row.is_null(column)) {
      rows.null();
      return;
    }
    switch (kind) {
      case Kind::integer:
        rows.integer(row.column_int(column));
        break;
      case Kind::real:
        rows.real(row.column_real(column));
        break;
      case Kind::text:
        rows.text(row.column_text(column));
        break;
      case Kind::blob:
        rows.bytes(row.column_blob(column));
        break;
    }
  }

  const store::Database& db_;
  PgConnection& pg_;
  const SyncOptions& options_;
  SyncCounts& counts_;
  const std::function<void(const SyncProgress&)>& progress_;
  std::map<std::int64_t, ArchivedSession> archived_;  // the station's sessions in the archive, as the pass began
};

}  // namespace

std::string default_station() {
  char name[HOST_NAME_MAX + 1] = {};
  if (::gethostname(name, sizeof name - 1) != 0 || name[0] == '\0') return "localhost";
  return name;
}

SyncCounts sync_to_archive(const std::filesystem::path& store_path, PgConnection& pg, const SyncOptions& options,
                           const std::function<void(const SyncProgress&)>& progress) {
  if (options.station.empty()) throw std::invalid_argument("the station name is empty");
  if (options.batch_rows == 0) throw std::invalid_argument("batch_rows must be at least 1");
  store::Database db(store_path, /*read_only=*/true);
  const std::int64_t schema_version = store::open_schema(db, /*read_only=*/true);
  const std::vector<LocalSession> sessions = local_sessions(db, schema_version, options.session);
  ensure_archive_schema(pg);
  SyncCounts counts;
  SessionSync session_sync(db, pg, options, counts, progress);
  for (const LocalSession& s : sessions) {
    if (!session_sync.sync(s)) break;
  }
  return counts;
}

}  // namespace imubridge::archive
