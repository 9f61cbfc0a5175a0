#include "store/schema.hpp"

#include <array>
#include <string>
#include <string_view>

namespace imubridge::store {
namespace {

// Measurement columns (SI values, estimates, reference) are declared without a type on purpose: a REAL column
// would let SQLite store -0.0 as the integer 0, and replay compares values bit for bit. NULL stands for "absent" or
// for NaN, which SQLite cannot store. Every per-session row carries session_id so that one index on it returns "all
// of session S in insertion order" without a sort; the rowid (id) is that order.
constexpr std::string_view kSchemaV1 = R"sql(
CREATE TABLE sessions (
  id INTEGER PRIMARY KEY,
  kind TEXT NOT NULL,
  source TEXT NOT NULL,
  started_wall_ns INTEGER NOT NULL,
  ended_wall_ns INTEGER,
  config TEXT NOT NULL,
  software_version TEXT NOT NULL
);
CREATE TABLE links (
  id INTEGER PRIMARY KEY,
  session_id INTEGER NOT NULL REFERENCES sessions (id),
  name TEXT NOT NULL,
  protocol TEXT NOT NULL,
  device TEXT NOT NULL,
  UNIQUE (session_id, id)  -- lets rows name (session_id, link_id) and have both checked
);
CREATE TABLE chunks (
  id INTEGER PRIMARY KEY,
  session_id INTEGER NOT NULL,
  link_id INTEGER NOT NULL,
  direction TEXT NOT NULL CHECK (direction IN ('rx', 'tx')),
  recv_mono_ns INTEGER NOT NULL,
  recv_wall_ns INTEGER NOT NULL,
  bytes BLOB NOT NULL,
  FOREIGN KEY (session_id, link_id) REFERENCES links (session_id, id)
);
CREATE INDEX chunks_by_session ON chunks (session_id);
CREATE TABLE samples (
  id INTEGER PRIMARY KEY,
  session_id INTEGER NOT NULL,
  link_id INTEGER NOT NULL,
  seq INTEGER NOT NULL,
  device_time_us INTEGER NOT NULL,
  recv_mono_ns INTEGER NOT NULL,
  ax, ay, az,
  gx, gy, gz,
  mx, my, mz,
  temperature_c,
  raw BLOB,
  FOREIGN KEY (session_id, link_id) REFERENCES links (session_id, id)
);
CREATE INDEX samples_by_session ON samples (session_id);
CREATE TABLE events (
  id INTEGER PRIMARY KEY,
  session_id INTEGER NOT NULL REFERENCES sessions (id),
  link_id INTEGER,
  mono_ns INTEGER NOT NULL,
  wall_ns INTEGER NOT NULL,
  kind TEXT NOT NULL,
  count INTEGER NOT NULL,
  detail TEXT NOT NULL,
  FOREIGN KEY (session_id, link_id) REFERENCES links (session_id, id)
);
CREATE INDEX events_by_session ON events (session_id);
CREATE TABLE runs (
  id INTEGER PRIMARY KEY,
  session_id INTEGER NOT NULL REFERENCES sessions (id),
  kind TEXT NOT NULL,
  params TEXT NOT NULL,
  created_wall_ns INTEGER NOT NULL,
  software_version TEXT NOT NULL
);
CREATE TABLE estimates (
  id INTEGER PRIMARY KEY,
  run_id INTEGER NOT NULL REFERENCES runs (id),
  link_id INTEGER NOT NULL REFERENCES links (id),
  seq INTEGER NOT NULL,
  t_s, fx, fy, vx, vy, var_vx, var_vy
);
CREATE INDEX estimates_by_run ON estimates (run_id);
CREATE TABLE reference (
  id INTEGER PRIMARY KEY,
  session_id INTEGER NOT NULL REFERENCES sessions (id),
  t_ns INTEGER NOT NULL,
  px, py, pz,
  qw, qx, qy, qz,
  vx, vy, vz
);
CREATE INDEX reference_by_session ON reference (session_id);
)sql";

void create_schema_v1(Database& db) {
  db.exec(kSchemaV1);
  db.exec("PRAGMA application_id = " + std::to_string(kApplicationId));
}

// Who writes each session, so a later start can tell a session whose writer died (it stays open forever) from one
// still being recorded (store/process_identity.hpp); and whether an ending was written by such a recovery. Sessions
// of version 1 have no writer: they are never taken for interrupted.
constexpr std::string_view kSchemaV2 = R"sql(
ALTER TABLE sessions ADD COLUMN writer_pid INTEGER;
ALTER TABLE sessions ADD COLUMN writer_boot_id TEXT;
ALTER TABLE sessions ADD COLUMN writer_start_ticks INTEGER;
ALTER TABLE sessions ADD COLUMN interrupted INTEGER NOT NULL DEFAULT 0;
)sql";

void add_session_writers(Database& db) { db.exec(kSchemaV2); }

constexpr std::array<MigrationStep, kSchemaVersion> kMigrations{create_schema_v1, add_session_writers};

std::int64_t user_version(const Database& db) { return db.query_int("PRAGMA user_version"); }

StoreError newer_schema(const Database& db, std::int64_t version, std::size_t newest) {
  return StoreError(db.name() + " was written by a newer imubridge (schema " + std::to_string(version) +
                    ", this build reads up to " + std::to_string(newest) + ")");
}

}  // namespace

std::span<const MigrationStep> migrations() { return kMigrations; }

void migrate(Database& db, std::span<const MigrationStep> steps) {
  db.exec("BEGIN IMMEDIATE");
  try {
    // Read inside the transaction: another process may have migrated the file since the caller looked.
    const std::int64_t from = user_version(db);
    if (from > static_cast<std::int64_t>(steps.size())) throw newer_schema(db, from, steps.size());
    for (auto step = steps.begin() + from; step != steps.end(); ++step) (*step)(db);
    db.exec("PRAGMA user_version = " + std::to_string(steps.size()));
    db.exec("COMMIT");
  } catch (...) {
    db.rollback();
    throw;
  }
}

std::int64_t open_schema(Database& db, bool read_only) {
  // The first read of the file: a file that is not SQLite at all fails here, with "file is not a database".
  const bool empty = db.query_int("SELECT count(*) FROM sqlite_schema") == 0;
  const std::int64_t application_id = db.query_int("PRAGMA application_id");
  if (!empty && application_id != kApplicationId) {
    throw StoreError(db.name() + " is a SQLite database of another program (application_id " +
                     std::to_string(application_id) + "), not an imubridge one");
  }
  const std::int64_t version = user_version(db);
  if (version > kSchemaVersion) throw newer_schema(db, version, kSchemaVersion);
  if (version == kSchemaVersion) return version;
  if (read_only) {
    if (version >= kOldestReadableVersion) return version;
    throw StoreError(db.name() + " has schema " + std::to_string(version) + " and needs an upgrade to " +
                     std::to_string(kSchemaVersion) + ", which a read-only open cannot do");
  }
  migrate(db, migrations());
  return kSchemaVersion;
}

}  // namespace imubridge::store
