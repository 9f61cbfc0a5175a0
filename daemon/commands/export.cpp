// `imubridge export`: one table of a session as CSV or JSON Lines, for notebooks, PlotJuggler and other tools.
#include "replay/export.hpp"

#include <CLI/CLI.hpp>
#include <cstdio>
#include <iostream>
#include <optional>
#include <stdexcept>
#include <string>

#include "daemon/command.hpp"
#include "fileio/whole_file.hpp"
#include "replay/session_lookup.hpp"

namespace imubridge::cli {
namespace {

struct ExportCommandOptions {
  std::string db, what, format = "csv", out;
  std::int64_t session = 0;
  std::optional<std::int64_t> run;
};

int run_export(const ExportCommandOptions& o) {
  replay::require_existing_store(o.db);
  const store::Store store(o.db, {.read_only = true});
  const auto table = replay::parse_export_table(o.what);
  const auto format = replay::parse_export_format(o.format);
  if (o.out.empty()) {
    std::ios::sync_with_stdio(false);
    replay::export_table(store, o.session, table, o.run, format, std::cout);
  } else {
    fileio::WholeFile file(o.out);  // a failed export leaves an earlier FILE as it was
    replay::export_table(store, o.session, table, o.run, format, file.stream());
    file.commit();
  }
  // Once it worked: a mistake is one line.
  std::fprintf(stderr, "%s\n", replay::describe_state(replay::find_session(store, o.session)).c_str());
  return 0;
}

const RegisterCommand kExport([](CLI::App& app) -> CommandRunner {
  auto o = std::make_shared<ExportCommandOptions>();
  auto* cmd = app.add_subcommand("export", "Write one table of a session as CSV or JSON Lines");
  cmd->add_option("--db", o->db, "The session store")->required();
  cmd->add_option("--session", o->session, "The session")->required();
  cmd->add_option("--what", o->what, "The table")
      ->check(CLI::IsMember({"samples", "estimates", "reference", "events"}))
      ->required();
  cmd->add_option("--run", o->run, "The run whose estimates to write (needed when the session has several)");
  cmd->add_option("--format", o->format, "Output format")
      ->check(CLI::IsMember({"csv", "jsonl"}))
      ->capture_default_str();
  cmd->add_option("--out", o->out, "Output file, written whole or not at all (default: stdout)");
  cmd->footer("Columns are the store's (docs/storage.md). Absent values and NaN are empty in CSV, null in JSON.");
  return [o] { return run_export(*o); };
});

}  // namespace
}  // namespace imubridge::cli
