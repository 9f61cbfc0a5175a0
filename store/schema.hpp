#pragma once
// The database schema, its version, and the migrations that bring an older file up to it. docs/storage.md describes
// every table and column.
#include <cstdint>
#include <span>

#include "store/sqlite.hpp"

namespace imubridge::store {

// PRAGMA application_id of an imubridge database ("IMUB"), so neither we nor `file` mistake another program's.
inline constexpr std::int32_t kApplicationId = 0x494D5542;
// PRAGMA user_version this build writes, and the newest it reads.
inline constexpr std::int64_t kSchemaVersion = 2;
// The oldest schema a read-only open reads as it is (the readers take what later versions added as absent), so that
// exporting or replaying a file recorded by an older imubridge needs no write access.
inline constexpr std::int64_t kOldestReadableVersion = 1;

// One step upgrades a database from schema version N (its index in the list) to N + 1.
using MigrationStep = void (*)(Database&);

// This build's steps, kSchemaVersion of them: step 0 creates the schema in an empty database.
std::span<const MigrationStep> migrations();

// Runs the steps from the database's user_version to steps.size(), then sets user_version, all in one transaction:
// a failing step leaves the file as it was. Throws StoreError if the database is newer than the steps.
void migrate(Database& db, std::span<const MigrationStep> steps);

// Checks that `db` is an empty database or an imubridge one this build can read, and migrates it to kSchemaVersion
// unless `read_only`, in which case a schema older than kOldestReadableVersion is an error. Returns the schema
// version the file now has. Throws StoreError with a one-line reason.
std::int64_t open_schema(Database& db, bool read_only);

}  // namespace imubridge::store
