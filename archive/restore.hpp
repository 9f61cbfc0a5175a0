#pragma once
// One archived session brought back into a local store, as a new session of that file: every tool (identify,
// diagnose, replay, export) then reads it through the one store API it already uses, rather than each learning
// PostgreSQL. docs/storage.md, "The archive".
#include <cstdint>
#include <filesystem>
#include <string>

#include "archive/pg_connection.hpp"
#include "store/store.hpp"

namespace imubridge::archive {

struct RestoredSession {
  std::int64_t local_session = 0;  // its id in the local store
  std::int64_t samples = 0, estimates = 0, events = 0, reference = 0, chunks = 0;
};

// Copies session `session` of `station` from the archive into the store at `local_path` (created if missing, and only
// once the session is found): the session, its links and runs (renumbered as the file numbers them), and every row
// in its original order. The session is ended as the archive has it (one still open in the archive stays open).
// Throws ArchiveError if the archive has no such session; a failure half-way leaves the local session incomplete,
// and says so.
RestoredSession restore_session(PgConnection& pg, const std::string& station, std::int64_t session,
                                const std::filesystem::path& local_path);

}  // namespace imubridge::archive
