#pragma once
// Finding what a command names in a store, with one-line errors a user can act on (std::invalid_argument).
#include <cstdint>
#include <filesystem>
#include <string>

#include "store/store.hpp"

namespace imubridge::replay {

// Opening a missing file would create an empty store: readers refuse that with "<path>: no such file".
void require_existing_store(const std::filesystem::path& db);
// "no session 7 in the store (its sessions: 1-3, 5)".
store::Session find_session(const store::Store& store, std::int64_t session);
// "session 3: interrupted (its writer, process 812, ended without ending it; it ends at its last stored time, 12.4 s
// after its start)", "session 3: ended after 60.0 s", "session 3: open (being written, or its writer's end is not
// known yet)": what readers print before using a session, which reads the same in every state.
std::string describe_state(const store::Session& session);
// "session 2 has no run 9 (its runs: 3 live, 4 replay)".
store::Run find_run(const store::Store& store, std::int64_t session, std::int64_t run);

}  // namespace imubridge::replay
