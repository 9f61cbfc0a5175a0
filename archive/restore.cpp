#include "archive/restore.hpp"

#include <map>
#include <optional>
#include <string>

#include "archive/archive_schema.hpp"
#include "archive/copy_format.hpp"

namespace imubridge::archive {
namespace {

// samples.raw: ten little-endian int32 (docs/storage.md).
std::array<std::int32_t, 10> decode_raw(const std::vector<std::uint8_t>& bytes) {
  std::array<std::int32_t, 10> raw{};
  if (bytes.size() != 4 * raw.size()) {
    throw ArchiveError("the archive has a sample with " + std::to_string(bytes.size()) +
                       " bytes of raw counts, not 40");
  }
  for (std::size_t i = 0; i < raw.size(); ++i) {
    std::uint32_t value = 0;
    for (std::size_t b = 0; b < 4; ++b) value |= std::uint32_t{bytes[4 * i + b]} << (8 * b);
    raw[i] = static_cast<std::int32_t>(value);
  }
  return raw;
}

class SessionRestore {
 public:
  SessionRestore(PgConnection& pg, const std::string& station, std::int64_t session,
                 const std::filesystem::path& local_path)
      : pg_(pg), local_path_(local_path), station_(station), session_(session) {}

  RestoredSession run() {
    const PgResult s = pg_.query(
        "SELECT kind, source, config, started_wall_ns, software_version, ended_wall_ns FROM sessions "
        "WHERE station = $1 AND id = $2",
        {station_, std::to_string(session_)});
    if (s.rows() == 0) {
      throw ArchiveError(pg_.name() + " has no session " + std::to_string(session_) + " of station '" + station_ + "'" +
                         stations_hint());
    }
    // Opened (or created) only now: a session that is not there leaves no empty store behind.
    local_store_.emplace(local_path_);
    result_.local_session = local_store_->begin_session({.kind = s.text(0, 0),
                                                         .source = s.text(0, 1),
                                                         .config = s.text(0, 2),
                                                         .started_wall_ns = s.integer(0, 3),
                                                         .software_version = s.text(0, 4)});
    try {
      copy_rows(s.is_null(0, 5) ? std::nullopt : std::optional(s.integer(0, 5)));
    } catch (const std::exception& e) {
      throw ArchiveError(std::string(e.what()) + "; local session " + std::to_string(result_.local_session) +
                         " is incomplete");
    }
    return result_;
  }

 private:
  std::string stations_hint() {
    const PgResult stations = pg_.query("SELECT DISTINCT station FROM sessions ORDER BY station LIMIT 20");
    if (stations.rows() == 0) return " (it has no sessions)";
    std::string hint = " (stations: ";
    for (int i = 0; i < stations.rows(); ++i) hint += (i ? ", " : "") + stations.text(i, 0);
    return hint + ")";
  }

  // COPY (SELECT columns FROM table WHERE <this session> ORDER BY id) TO STDOUT, a line at a time.
  void each_row(const std::string& columns, const std::string& table, const std::string& where_more,
                const std::function<void(const CopyLine&)>& visit) {
    pg_.copy_out("COPY (SELECT " + columns + " FROM " + table + " WHERE station = " + pg_.literal(station_) +
                     " AND session_id = " + std::to_string(session_) + where_more + " ORDER BY id) TO STDOUT",
                 [&](std::string_view line) { visit(CopyLine(line)); });
  }

  std::int64_t local_link(std::int64_t archived) const {
    const auto found = links_.find(archived);
    if (found == links_.end()) {
      throw ArchiveError("the archive has rows of session " + std::to_string(session_) + " naming link " +
                         std::to_string(archived) + ", which it lacks");
    }
    return found->second;
  }

  void copy_rows(std::optional<std::int64_t> ended_wall_ns) {
    const std::int64_t local = result_.local_session;
    each_row("id, name, protocol, device", "links", "", [&](const CopyLine& row) {
      links_[row.integer(0)] = local_store_->add_link(local, row.text(1), row.text(2), row.text(3));
    });
    std::map<std::int64_t, std::int64_t> runs;
    each_row("id, kind, params, created_wall_ns, software_version", "runs", "", [&](const CopyLine& row) {
      runs[row.integer(0)] = local_store_->begin_run(local, {.kind = row.text(1),
                                                             .params_json = row.text(2),
                                                             .created_wall_ns = row.integer(3),
                                                             .software_version = row.text(4)});
    });
    each_row("link_id, direction, recv_mono_ns, recv_wall_ns, bytes", "chunks", "", [&](const CopyLine& row) {
      const auto bytes = row.bytes(4);
      local_store_->append_chunk(local, local_link(row.integer(0)),
                                 row.text(1) == "tx" ? store::Direction::tx : store::Direction::rx, row.integer(2),
                                 row.integer(3), bytes);
      ++result_.chunks;
    });
    each_row("link_id, seq, device_time_us, recv_mono_ns, ax, ay, az, gx, gy, gz, mx, my, mz, temperature_c, raw",
             "samples", "", [&](const CopyLine& row) {
               protocol::Sample sample;
               sample.link_id = local_link(row.integer(0));
               sample.seq = static_cast<std::uint64_t>(row.integer(1));  // the same bits, as the store keeps them
               sample.device_time_us = row.integer(2);
               sample.recv_mono_ns = row.integer(3);
               sample.accel = {row.real(4), row.real(5), row.real(6)};
               sample.gyro = {row.real(7), row.real(8), row.real(9)};
               // A group of columns is absent when all of it is NULL (docs/storage.md).
               sample.has_mag = !(row.is_null(10) && row.is_null(11) && row.is_null(12));
               if (sample.has_mag) sample.mag = {row.real(10), row.real(11), row.real(12)};
               sample.has_temperature = !row.is_null(13);
               if (sample.has_temperature) sample.temperature_c = row.real(13);
               sample.has_raw = !row.is_null(14);
               if (sample.has_raw) sample.raw = decode_raw(row.bytes(14));
               local_store_->append_sample(local, sample);
               ++result_.samples;
             });
    each_row("link_id, mono_ns, wall_ns, kind, count, detail", "events", "", [&](const CopyLine& row) {
      const auto link = row.optional_integer(0);
      local_store_->append_event(local, {.link_id = link ? std::optional(local_link(*link)) : std::nullopt,
                                         .mono_ns = row.integer(1),
                                         .wall_ns = row.integer(2),
                                         .kind = row.text(3),
                                         .count = row.integer(4),
                                         .detail = row.text(5)});
      ++result_.events;
    });
    for (const auto& run : runs) {
      const std::int64_t local_run = run.second;  // a lambda may not capture a structured binding before clang 16
      each_row("link_id, seq, t_s, fx, fy, vx, vy, var_vx, var_vy", "estimates",
               " AND run_id = " + std::to_string(run.first), [&](const CopyLine& row) {
                 local_store_->append_estimate(local_run, {.link_id = local_link(row.integer(0)),
                                                           .seq = static_cast<std::uint64_t>(row.integer(1)),
                                                           .t_s = row.real(2),
                                                           .fx = row.real(3),
                                                           .fy = row.real(4),
                                                           .vx = row.real(5),
                                                           .vy = row.real(6),
                                                           .var_vx = row.real(7),
                                                           .var_vy = row.real(8)});
                 ++result_.estimates;
               });
    }
    each_row("t_ns, px, py, pz, qw, qx, qy, qz, vx, vy, vz", "reference", "", [&](const CopyLine& row) {
      store::ReferenceRow reference{.t_ns = row.integer(0),
                                    .position = {row.real(1), row.real(2), row.real(3)},
                                    .quat_wxyz = {row.real(4), row.real(5), row.real(6), row.real(7)}};
      if (!(row.is_null(8) && row.is_null(9) && row.is_null(10))) {
        reference.velocity = std::array{row.real(8), row.real(9), row.real(10)};
      }
      local_store_->append_reference(local, reference);
      ++result_.reference;
    });
    local_store_->commit();
    if (ended_wall_ns) local_store_->end_session(local, *ended_wall_ns);
  }

  PgConnection& pg_;
  std::filesystem::path local_path_;
  std::optional<store::Store> local_store_;
  std::string station_;
  std::int64_t session_;
  std::map<std::int64_t, std::int64_t> links_;  // archived link id -> local link id
  RestoredSession result_;
};

}  // namespace

RestoredSession restore_session(PgConnection& pg, const std::string& station, std::int64_t session,
                                const std::filesystem::path& local_path) {
  require_archive_schema(pg);
  // Doubles in their shortest exact form and bytea as hex, whatever the server's defaults: the rows come back bit
  // for bit.
  pg.exec("SET extra_float_digits = 3; SET bytea_output = 'hex'");
  // One snapshot for the whole session, so a sync writing into it meanwhile cannot tear it.
  RestoredSession restored;
  pg.exec("BEGIN ISOLATION LEVEL REPEATABLE READ READ ONLY");
  try {
    restored = SessionRestore(pg, station, session, local_path).run();
    pg.exec("COMMIT");
  } catch (...) {
    pg.rollback();
    throw;
  }
  return restored;
}

}  // namespace imubridge::archive
