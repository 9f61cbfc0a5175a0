#pragma once
// The archive's schema in PostgreSQL: the store's tables (docs/storage.md) with a station column, so the sessions
// of every ground station live side by side, each keyed by (station, its local id). Plain PostgreSQL, no extension,
// so TimescaleDB or Citus can take it over later. Versioned like the store's: docs/storage.md, "The archive".
#include <cstdint>

#include "archive/pg_connection.hpp"

namespace imubridge::archive {

// The schema this build writes and reads.
inline constexpr std::int64_t kArchiveSchemaVersion = 1;

// Creates the schema if the database has none, or upgrades an older one, in one transaction under a lock, so
// twenty stations starting at once create it once. Throws ArchiveError for an archive of a newer imubridge.
void ensure_archive_schema(PgConnection& pg);

// Checks that the database holds an archive this build can read (without creating anything).
void require_archive_schema(PgConnection& pg);

}  // namespace imubridge::archive
