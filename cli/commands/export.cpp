// `imubridge export`: one table of a session as CSV or JSON Lines, or the whole session as MCAP, for notebooks,
// PlotJuggler, Foxglove and other tools.
#include "replay/export.hpp"

#include <CLI/CLI.hpp>
#include <cstdio>
#include <iostream>
#include <optional>
#include <stdexcept>
#include <string>

#include "cli/command.hpp"
#include "fileio/whole_file.hpp"
#include "replay/session_lookup.hpp"

namespace imubridge::cli {
namespace {

struct ExportCommandOptions {
  std::string db, what, format = "csv", time = "session", out;
  std::int64_t session = 0;
  std::optional<std::int64_t> run;
};

int run_export(const ExportCommandOptions& o) {
  replay::require_existing_store(o.db);
  const store::Store store(o.db, {.read_only = true});
  const auto format = replay::parse_export_format(o.format);
  const auto time = replay::parse_export_time(o.time);
  if (format == replay::ExportFormat::mcap && o.out.empty()) {
    throw std::invalid_argument("--format mcap writes a file: give --out FILE.mcap");
  }
  if (format == replay::ExportFormat::mcap && !o.what.empty()) {
    throw std::invalid_argument("an MCAP export holds every table: leave out --what");
  }
  if (format != replay::ExportFormat::mcap && o.what.empty()) {
    throw std::invalid_argument("--what is required: samples, estimates, reference or events");
  }
  // What was written and on which clock, said once it worked (a mistake is one line).
  const auto write = [&](std::ostream& out) -> std::string {
    if (format == replay::ExportFormat::mcap) {
      const auto n = replay::export_mcap(store, o.session, o.run, out);
      return std::to_string(n.samples) + " samples, " + std::to_string(n.estimates) + " estimates, " +
             std::to_string(n.reference) + " reference rows, " + std::to_string(n.events) +
             " events; log time: the session's monotonic clock, ns (each message also has session_t_s)";
    }
    replay::export_table(store, o.session, replay::parse_export_table(o.what), o.run, format, time, out);
    return std::string("times: ") + replay::describe_export_time(time);
  };
  std::string written;
  if (o.out.empty()) {
    std::ios::sync_with_stdio(false);
    written = write(std::cout);
  } else {
    fileio::WholeFile file(o.out);  // a failed export leaves an earlier FILE as it was
    written = write(file.stream());
    file.commit();
  }
  std::fprintf(stderr, "%s\n%s\n", replay::describe_state(replay::find_session(store, o.session)).c_str(),
               written.c_str());
  return 0;
}

const RegisterCommand kExport([](CLI::App& app) -> CommandRunner {
  auto o = std::make_shared<ExportCommandOptions>();
  auto* cmd = app.add_subcommand("export", "Write one table of a session as CSV or JSON Lines, or all of it as MCAP");
  cmd->add_option("--db", o->db, "The session store")->required();
  cmd->add_option("--session", o->session, "The session")->required();
  cmd->add_option("--what", o->what, "The table (csv and jsonl)")
      ->check(CLI::IsMember({"samples", "estimates", "reference", "events"}));
  cmd->add_option("--run", o->run, "The run whose estimates to write (needed when the session has several)");
  cmd->add_option("--format", o->format, "Output format")
      ->check(CLI::IsMember({"csv", "jsonl", "mcap"}))
      ->capture_default_str();
  cmd->add_option("--time", o->time,
                  "session: seconds since the first sample (as identify, diagnose and import speak); recorded: the "
                  "store's clocks")
      ->check(CLI::IsMember({"session", "recorded"}))
      ->capture_default_str();
  cmd->add_option("--out", o->out, "Output file, written whole or not at all (default: stdout; mcap needs one)");
  cmd->footer(
      "Columns are the store's (docs/storage.md) but for the times (--time). Absent values and NaN are empty in CSV, "
      "null in JSON. MCAP: every table of the session as channels for Foxglove and PlotJuggler (docs/replay.md).");
  return [o] { return run_export(*o); };
});

}  // namespace
}  // namespace imubridge::cli
