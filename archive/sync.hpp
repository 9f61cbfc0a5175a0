#pragma once
// Copies the sessions of a local store into the archive, incrementally: what the archive already has is never sent
// again, and an interrupted sync (kill -9, the network gone) loses nothing and duplicates nothing. How: per
// (station, session, table) the archive's largest row id is where the copy resumes; rows follow in id order, in
// batches, each batch one PostgreSQL transaction, so a batch is in the archive whole or not at all. The archive's
// primary key (station, session, row id) refuses a second copy of any row, whatever runs at the same time.
// docs/storage.md, "The archive".
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <string_view>

#include "archive/pg_connection.hpp"

namespace imubridge::archive {

struct SyncOptions {
  // Names the store in the archive: its sessions are (station, local session id). One station, one store file.
  std::string station;
  std::optional<std::int64_t> session{};  // only this one; none: every session of the store
  bool chunks = false;                    // the raw byte chunks too (replay's input; the bulk of a store)
  std::size_t batch_rows = 20000;         // rows per transaction, at most (and at most 16 MiB of COPY data)
  // Asked between batches; true stops the pass there (what was committed stays, the next pass resumes).
  std::function<bool()> stop_requested{};
};

// Rows the pass copied, per table.
struct SyncCounts {
  std::int64_t sessions_added = 0, sessions_ended = 0;  // session rows created, endings written
  std::int64_t links = 0, runs = 0, samples = 0, estimates = 0, events = 0, reference = 0, chunks = 0;
  std::int64_t rows() const noexcept { return links + runs + samples + estimates + events + reference + chunks; }
};

// After each committed batch: the session, the table and the rows the batch held.
struct SyncProgress {
  std::int64_t session = 0;
  std::string_view table;
  std::int64_t rows = 0;
};

// One pass over the store at `store_path` (opened read-only, beside any recorder: WAL): every session (or the one
// asked) is brought up to date in the archive, whose schema is created if missing. A session still recording is
// copied as far as it is committed, and its ending follows in a later pass; the archive marks a session ended only
// once every row it had when it ended is in. Throws ArchiveError (PostgreSQL) or store::StoreError (the file), one
// line; everything committed before the failure stays and the next pass goes on from there.
SyncCounts sync_to_archive(const std::filesystem::path& store_path, PgConnection& pg, const SyncOptions& options,
                           const std::function<void(const SyncProgress&)>& progress = {});

// The host's name: the station of a store unless one is given.
std::string default_station();

}  // namespace imubridge::archive
