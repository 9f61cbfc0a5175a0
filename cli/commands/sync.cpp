// `imubridge sync`: a store's sessions into the fleet archive in PostgreSQL (--to), incrementally, or one archived
// session back into a local store (--from). docs/storage.md, "The archive".
#include "archive/sync.hpp"

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include "archive/restore.hpp"
#include "cli/command.hpp"
#include "daemon/config.hpp"
#include "replay/session_lookup.hpp"

namespace imubridge::cli {
namespace {

struct SyncCommandOptions {
  std::string to, from;
  std::string db = daemon::StoreConfig{}.path.string();
  std::string station;
  std::optional<std::int64_t> session;
  bool chunks = false;
  std::string password_file;
  std::size_t batch_rows = archive::SyncOptions{}.batch_rows;
};

archive::PgConnectOptions connect_options(const std::string& url, const SyncCommandOptions& o) {
  archive::PgConnectOptions options{.url = url};
  if (!o.password_file.empty()) options.password = archive::read_password_file(o.password_file);
  return options;
}

int run_sync_to(const SyncCommandOptions& o) {
  replay::require_existing_store(o.db);
  const std::string station = o.station.empty() ? archive::default_station() : o.station;
  const auto start = std::chrono::steady_clock::now();
  archive::PgConnection pg(connect_options(o.to, o));
  const auto counts = archive::sync_to_archive(
      o.db, pg, {.station = station, .session = o.session, .chunks = o.chunks, .batch_rows = o.batch_rows});
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (counts.rows() == 0 && counts.sessions_added == 0 && counts.sessions_ended == 0) {
    std::fprintf(stderr, "station '%s' (%s) in %s: nothing new, the archive is up to date\n", station.c_str(),
                 o.db.c_str(), pg.name().c_str());
    return 0;
  }
  std::fprintf(stderr,
               "station '%s' (%s) into %s: %lld sessions added, %lld ended; %lld samples, %lld estimates, %lld "
               "events, %lld reference rows, %lld chunks, %lld links, %lld runs in %.2f s (%.0f samples/s)\n",
               station.c_str(), o.db.c_str(), pg.name().c_str(), static_cast<long long>(counts.sessions_added),
               static_cast<long long>(counts.sessions_ended), static_cast<long long>(counts.samples),
               static_cast<long long>(counts.estimates), static_cast<long long>(counts.events),
               static_cast<long long>(counts.reference), static_cast<long long>(counts.chunks),
               static_cast<long long>(counts.links), static_cast<long long>(counts.runs), seconds,
               seconds > 0 ? static_cast<double>(counts.samples) / seconds : 0.0);
  return 0;
}

int run_sync_from(const SyncCommandOptions& o) {
  if (o.station.empty()) throw std::invalid_argument("--from needs --station: the station whose session to bring");
  if (!o.session) throw std::invalid_argument("--from needs --session: the station's session id in the archive");
  if (o.chunks) throw std::invalid_argument("--chunks is for --to: --from brings whatever the archive has");
  archive::PgConnection pg(connect_options(o.from, o));
  const auto r = archive::restore_session(pg, o.station, *o.session, o.db);
  std::fprintf(stderr,
               "station '%s' session %lld from %s into %s as session %lld: %lld samples, %lld estimates, %lld "
               "events, %lld reference rows, %lld chunks\n",
               o.station.c_str(), static_cast<long long>(*o.session), pg.name().c_str(), o.db.c_str(),
               static_cast<long long>(r.local_session), static_cast<long long>(r.samples),
               static_cast<long long>(r.estimates), static_cast<long long>(r.events),
               static_cast<long long>(r.reference), static_cast<long long>(r.chunks));
  std::printf("%lld\n", static_cast<long long>(r.local_session));  // last, as sim --db and import print theirs
  return 0;
}

const RegisterCommand kSync([](CLI::App& app) -> CommandRunner {
  auto o = std::make_shared<SyncCommandOptions>();
  auto* cmd = app.add_subcommand(
      "sync", "Copy a store's sessions into the fleet archive in PostgreSQL (--to), or bring one back (--from)");
  auto* direction = cmd->add_option_group("direction", "Which way (exactly one)");
  direction->add_option("--to", o->to,
                        "Archive URL (postgresql://user@host:5432/db): copy what it lacks of the store's sessions");
  direction->add_option("--from", o->from, "Archive URL: bring --session of --station back into --db as a new session");
  direction->require_option(1);
  cmd->add_option("--db", o->db, "The local session store")->capture_default_str();
  cmd->add_option("--station", o->station,
                  "The station's name in the archive (default for --to: this host's name); one per store file");
  cmd->add_option("--session", o->session, "Only this session (its local id for --to, the station's for --from)");
  cmd->add_flag("--chunks", o->chunks, "--to: the raw byte chunks too (replay's input; most of a store's size)");
  cmd->add_option("--password-file", o->password_file,
                  "The archive password, the file's first line (else the URL's, PGPASSWORD or ~/.pgpass)");
  cmd->add_option("--batch-rows", o->batch_rows, "--to: rows per PostgreSQL transaction")
      ->check(CLI::Range(std::size_t{1}, std::size_t{10'000'000}))
      ->capture_default_str();
  cmd->footer(
      "--to is incremental and idempotent: it sends only what the archive lacks, and a sync interrupted at any "
      "point (kill -9, the network gone) resumes where it stopped, never duplicating a row. A session still "
      "recording is copied as far as it goes and finished by the next sync. The archive's schema is created if "
      "missing. docs/storage.md, \"The archive\".");
  return [o] { return o->to.empty() ? run_sync_from(*o) : run_sync_to(*o); };
});

}  // namespace
}  // namespace imubridge::cli
