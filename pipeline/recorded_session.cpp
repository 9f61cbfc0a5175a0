#include "pipeline/recorded_session.hpp"

namespace imubridge::pipeline {

RecordedSession begin_recorded_session(store::Store& store, const SessionStart& start,
                                       const std::vector<SessionLink>& links) {
  nlohmann::json config = start.config;
  std::vector<RecordedLink> recorded;
  for (const SessionLink& link : links) recorded.push_back(link.recorded);
  add_recorded_links(config, recorded);
  RecordedSession session;
  session.id = store.begin_session(
      {.kind = start.kind, .source = start.source, .config = config.dump(), .started_wall_ns = start.started_wall_ns});
  try {
    if (!start.note.empty()) {
      store.append_event(
          session.id,
          {.mono_ns = start.note_mono_ns, .wall_ns = start.started_wall_ns, .kind = "note", .detail = start.note});
    }
    for (const SessionLink& link : links) {
      const RecordedLink& r = link.recorded;
      session.store_links.push_back(
          store.add_link(session.id, r.name, protocol::wire_format_name(r.format), link.device));
    }
    if (start.estimated_with) {
      session.run = store.begin_run(session.id, {.kind = start.kind,
                                                 .params_json = nlohmann::json(*start.estimated_with).dump(),
                                                 .created_wall_ns = start.started_wall_ns});
    }
  } catch (const store::StoreError&) {
    try {
      store.end_session(session.id, start.started_wall_ns);
    } catch (const store::StoreError&) {
    }
    throw;
  }
  return session;
}

void end_recorded_session(store::Store& store, std::int64_t session, std::int64_t ended_wall_ns) {
  store.end_session(session, ended_wall_ns);
  store.commit();
}

}  // namespace imubridge::pipeline
