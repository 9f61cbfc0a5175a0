#include "replay/session_lookup.hpp"

#include <cstdio>
#include <stdexcept>
#include <vector>

#include "replay/text_table.hpp"

namespace imubridge::replay {

void require_existing_store(const std::filesystem::path& db) {
  if (!std::filesystem::exists(db)) throw std::invalid_argument(db.string() + ": no such file");
}

store::Session find_session(const store::Store& store, std::int64_t session) {
  const auto sessions = store.sessions();
  std::vector<std::int64_t> ids;
  for (const auto& s : sessions) {
    if (s.id == session) return s;
    ids.push_back(s.id);
  }
  throw std::invalid_argument("no session " + std::to_string(session) + " in the store" +
                              (ids.empty() ? " (it has none)" : " (its sessions: " + format_ranges(ids) + ")"));
}

std::string describe_state(const store::Session& session) {
  const std::string head = "session " + std::to_string(session.id) + ": " + store::state_name(session);
  if (!session.ended_wall_ns) return head + " (being written, or its writer's end is not known yet)";
  char seconds[32];
  std::snprintf(seconds, sizeof seconds, "%.1f s",
                static_cast<double>(*session.ended_wall_ns - session.info.started_wall_ns) * 1e-9);
  if (!session.interrupted) return head + " after " + seconds;
  const std::string writer = session.writer ? ", process " + std::to_string(session.writer->pid) + "," : "";
  return head + " (its writer" + writer + " ended without ending it; it ends at its last stored time, " + seconds +
         " after its start)";
}

store::Run find_run(const store::Store& store, std::int64_t session, std::int64_t run) {
  std::string known;
  for (const auto& r : store.runs(session)) {
    if (r.id == run) return r;
    known += (known.empty() ? "" : ", ") + std::to_string(r.id) + " " + r.info.kind;
  }
  throw std::invalid_argument("session " + std::to_string(session) + " has no run " + std::to_string(run) +
                              (known.empty() ? " (it has none)" : " (its runs: " + known + ")"));
}

}  // namespace imubridge::replay
