#pragma once
// What a session holds, read back whole from the store: the assertions of the import tests.
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string_view>
#include <vector>

#include "store/store.hpp"

namespace imubridge::test {

inline std::vector<protocol::Sample> stored_samples(const store::Store& store, std::int64_t session) {
  std::vector<protocol::Sample> out;
  store.for_each_sample(session, std::nullopt, [&](const protocol::Sample& s) { out.push_back(s); });
  return out;
}

inline std::vector<store::ReferenceRow> stored_reference(const store::Store& store, std::int64_t session) {
  std::vector<store::ReferenceRow> out;
  store.for_each_reference(session, [&](const store::ReferenceRow& r) { out.push_back(r); });
  return out;
}

// The session's events of one kind, in order.
inline std::vector<store::Event> stored_events(const store::Store& store, std::int64_t session, std::string_view kind) {
  std::vector<store::Event> out;
  for (const auto& e : store.events(session)) {
    if (e.kind == kind) out.push_back(e);
  }
  return out;
}

// The session's configuration snapshot; null when there is no such session.
inline nlohmann::json session_config(const store::Store& store, std::int64_t session) {
  for (const auto& s : store.sessions()) {
    if (s.id == session) return nlohmann::json::parse(s.info.config);
  }
  return nullptr;
}

}  // namespace imubridge::test
