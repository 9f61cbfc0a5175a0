// `imubridge list`: the sessions of a store, one line each, with their state: ended, interrupted (its writer died
// without ending it) or open (being written).
#include <CLI/CLI.hpp>
#include <cstdio>
#include <ctime>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "cli/command.hpp"
#include "replay/session_lookup.hpp"
#include "store/store.hpp"

namespace imubridge::cli {
namespace {

struct ListCommandOptions {
  std::string db;
  bool json = false;
};

std::string utc(std::int64_t wall_ns) {
  const std::time_t seconds = static_cast<std::time_t>(wall_ns / 1'000'000'000);
  std::tm tm{};
  gmtime_r(&seconds, &tm);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%d %H:%M:%S", &tm);
  return text;
}

std::optional<double> duration_s(const store::Session& s) {
  if (!s.ended_wall_ns) return std::nullopt;
  return static_cast<double>(*s.ended_wall_ns - s.info.started_wall_ns) * 1e-9;
}

int run_list(const ListCommandOptions& o) {
  replay::require_existing_store(o.db);
  const store::Store store(o.db, {.read_only = true});
  const auto sessions = store.sessions();
  if (o.json) {
    nlohmann::json rows = nlohmann::json::array();
    for (const auto& s : sessions) {
      const auto seconds = duration_s(s);
      rows.push_back({{"session", s.id},
                      {"kind", s.info.kind},
                      {"state", store::state_name(s)},
                      {"started_wall_ns", s.info.started_wall_ns},
                      {"ended_wall_ns", s.ended_wall_ns ? nlohmann::json(*s.ended_wall_ns) : nlohmann::json()},
                      {"duration_s", seconds ? nlohmann::json(*seconds) : nlohmann::json()},
                      {"source", s.info.source},
                      {"software_version", s.info.software_version}});
    }
    std::printf("%s\n", rows.dump(2).c_str());
    return 0;
  }
  if (sessions.empty()) std::fprintf(stderr, "%s has no sessions\n", o.db.c_str());
  std::printf("%-8s %-7s %-12s %-20s %10s  %s\n", "session", "kind", "state", "started (UTC)", "seconds", "source");
  for (const auto& s : sessions) {
    const auto seconds = duration_s(s);
    char length[32] = "-";
    if (seconds) std::snprintf(length, sizeof length, "%.1f", *seconds);
    std::printf("%-8lld %-7s %-12s %-20s %10s  %s\n", static_cast<long long>(s.id), s.info.kind.c_str(),
                store::state_name(s), utc(s.info.started_wall_ns).c_str(), length, s.info.source.c_str());
  }
  return 0;
}

const RegisterCommand kList([](CLI::App& app) -> CommandRunner {
  auto o = std::make_shared<ListCommandOptions>();
  auto* cmd = app.add_subcommand("list",
                                 "List the sessions of a store: kind, state (ended, interrupted, open), "
                                 "start, length, source");
  cmd->add_option("--db", o->db, "The session store")->required();
  cmd->add_flag("--json", o->json, "One JSON array instead of text");
  cmd->footer(
      "An interrupted session's writer died without ending it; it ends at its last stored time and reads "
      "like any other (docs/storage.md).");
  return [o] { return run_list(*o); };
});

}  // namespace
}  // namespace imubridge::cli
