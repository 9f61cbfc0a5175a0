#include "archive/archive_schema.hpp"

#include <array>
#include <string>
#include <string_view>

namespace imubridge::archive {
namespace {

// pg_advisory_xact_lock key of schema changes ("IMUB", the store's application_id).
constexpr std::string_view kSchemaLock = "SELECT pg_advisory_xact_lock(1229804866)";

// Every table is the store's, with `station` first. Each row's key is (station, session_id, id): id is the row's id
// in its station's file, so the key is the row's identity wherever it is copied from, and a second copy of a row
// is refused. The key's order also makes "everything of one session in order" an index range, and "how far did
// this session get" (max(id)) one index probe: the sync's watermark is the data itself. estimates carries its
// run's session_id so that it too is keyed by session. Measurements are double precision: PostgreSQL keeps -0
// and every bit of a double. Only the small tables have foreign keys: the bulk rows are written after their
// session, link and run, and checking each of millions of rows would halve the copying speed.
constexpr std::string_view kArchiveV1 = R"sql(
CREATE TABLE sessions (
  station text NOT NULL,
  id bigint NOT NULL,
  kind text NOT NULL,
  source text NOT NULL,
  started_wall_ns bigint NOT NULL,
  ended_wall_ns bigint,
  config text NOT NULL,
  software_version text NOT NULL,
  writer_pid bigint,
  writer_boot_id text,
  writer_start_ticks bigint,
  interrupted integer NOT NULL DEFAULT 0,
  synced_through text,
  PRIMARY KEY (station, id)
);
CREATE TABLE links (
  station text NOT NULL,
  session_id bigint NOT NULL,
  id bigint NOT NULL,
  name text NOT NULL,
  protocol text NOT NULL,
  device text NOT NULL,
  PRIMARY KEY (station, session_id, id),
  FOREIGN KEY (station, session_id) REFERENCES sessions (station, id)
);
CREATE TABLE runs (
  station text NOT NULL,
  session_id bigint NOT NULL,
  id bigint NOT NULL,
  kind text NOT NULL,
  params text NOT NULL,
  created_wall_ns bigint NOT NULL,
  software_version text NOT NULL,
  PRIMARY KEY (station, session_id, id),
  FOREIGN KEY (station, session_id) REFERENCES sessions (station, id)
);
CREATE TABLE chunks (
  station text NOT NULL,
  session_id bigint NOT NULL,
  id bigint NOT NULL,
  link_id bigint NOT NULL,
  direction text NOT NULL CHECK (direction IN ('rx', 'tx')),
  recv_mono_ns bigint NOT NULL,
  recv_wall_ns bigint NOT NULL,
  bytes bytea NOT NULL,
  PRIMARY KEY (station, session_id, id)
);
CREATE TABLE samples (
  station text NOT NULL,
  session_id bigint NOT NULL,
  id bigint NOT NULL,
  link_id bigint NOT NULL,
  seq bigint NOT NULL,
  device_time_us bigint NOT NULL,
  recv_mono_ns bigint NOT NULL,
  ax double precision, ay double precision, az double precision,
  gx double precision, gy double precision, gz double precision,
  mx double precision, my double precision, mz double precision,
  temperature_c double precision,
  raw bytea,
  PRIMARY KEY (station, session_id, id)
);
CREATE TABLE events (
  station text NOT NULL,
  session_id bigint NOT NULL,
  id bigint NOT NULL,
  link_id bigint,
  mono_ns bigint NOT NULL,
  wall_ns bigint NOT NULL,
  kind text NOT NULL,
  count bigint NOT NULL,
  detail text NOT NULL,
  PRIMARY KEY (station, session_id, id)
);
CREATE TABLE estimates (
  station text NOT NULL,
  session_id bigint NOT NULL,
  run_id bigint NOT NULL,
  id bigint NOT NULL,
  link_id bigint NOT NULL,
  seq bigint NOT NULL,
  t_s double precision, fx double precision, fy double precision,
  vx double precision, vy double precision, var_vx double precision, var_vy double precision,
  PRIMARY KEY (station, session_id, run_id, id)
);
CREATE TABLE reference (
  station text NOT NULL,
  session_id bigint NOT NULL,
  id bigint NOT NULL,
  t_ns bigint NOT NULL,
  px double precision, py double precision, pz double precision,
  qw double precision, qx double precision, qy double precision, qz double precision,
  vx double precision, vy double precision, vz double precision,
  PRIMARY KEY (station, session_id, id)
);
)sql";

using ArchiveStep = std::string_view;
constexpr std::array<ArchiveStep, kArchiveSchemaVersion> kArchiveSteps{kArchiveV1};

// The version table exists once any imubridge has touched the database; no row: version 0.
std::int64_t archive_version(PgConnection& pg) {
  const PgResult exists = pg.query("SELECT to_regclass('imubridge_archive') IS NOT NULL");
  if (exists.text(0, 0) != "t") return 0;
  const PgResult version = pg.query("SELECT max(version) FROM imubridge_archive");
  return version.is_null(0, 0) ? 0 : version.integer(0, 0);
}

void refuse_newer(const PgConnection& pg, std::int64_t version) {
  if (version > kArchiveSchemaVersion) {
    throw ArchiveError(pg.name() + " is an archive of a newer imubridge (schema " + std::to_string(version) +
                       ", this build reads up to " + std::to_string(kArchiveSchemaVersion) + ")");
  }
}

}  // namespace

void ensure_archive_schema(PgConnection& pg) {
  // Every pass starts here: an archive that is up to date costs one read, and no privilege to create anything.
  if (archive_version(pg) == kArchiveSchemaVersion) return;
  pg.transaction([&] {
    pg.exec(kSchemaLock);  // held to COMMIT: another station's sync waits here, then finds the schema made
    pg.exec("CREATE TABLE IF NOT EXISTS imubridge_archive (version integer NOT NULL)");
    const std::int64_t version = archive_version(pg);
    refuse_newer(pg, version);
    for (auto step = kArchiveSteps.begin() + version; step != kArchiveSteps.end(); ++step) pg.exec(*step);
    if (version < kArchiveSchemaVersion) {
      pg.exec("DELETE FROM imubridge_archive");
      pg.exec("INSERT INTO imubridge_archive (version) VALUES (" + std::to_string(kArchiveSchemaVersion) + ")");
    }
  });
}

void require_archive_schema(PgConnection& pg) {
  const std::int64_t version = archive_version(pg);
  if (version == 0) throw ArchiveError(pg.name() + " holds no imubridge archive (nothing was synced into it)");
  refuse_newer(pg, version);
}

}  // namespace imubridge::archive
