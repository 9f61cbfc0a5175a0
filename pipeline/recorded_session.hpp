#pragma once
// Beginning and ending a recorded session, for every writer of sessions (the daemon, `sim --db`, imports): the
// session row with its configuration snapshot, which names each link's wire format, calibration and IMU axes so
// replay can decode the bytes again; a store link per link; and, for a writer that estimates, the run its estimates go
// to. A session is never left half begun: if any of it fails, what began is ended. What is recorded into it is the
// SessionRecording's (pipeline/link_recorder.hpp), a sink of the engine that decodes the links.
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "estimator/params.hpp"
#include "pipeline/mavlink_reference.hpp"
#include "pipeline/session_config.hpp"
#include "store/store.hpp"

namespace imubridge::pipeline {

struct SessionLink {
  RecordedLink recorded;  // name, wire format, calibration, IMU axes
  std::string device;     // for people, the store link's device: "/dev/ttyUSB0 @ 921600 baud", "EuRoC imu0, ..."
  // A MAVLink link whose positions and attitudes become the session's reference (SessionRecording).
  std::optional<MavlinkReference::Choice> mavlink_reference{};
};

struct SessionStart {
  std::string kind;         // "live", "sim", "import"
  std::string source{};     // for people: what produced it
  nlohmann::json config{};  // the writer's own snapshot; the links' recording settings are added to it
  std::int64_t started_wall_ns = 0;
  std::string note{};  // when set, the session's first event: what it continues, and why
  std::int64_t note_mono_ns = 0;
  // A run for the estimates made while recording, holding the parameters they were made with.
  std::optional<estimator::ModelParams> estimated_with{};
};

// A session as begun: its id, its run (when estimated_with was given), and each link's store link, in the order the
// links were given.
struct RecordedSession {
  std::int64_t id = 0;
  std::optional<std::int64_t> run{};
  std::vector<std::int64_t> store_links{};
};

// Begins the session, its links and its run. Throws store::StoreError when the store refuses any of it, after
// ending the session if it had begun and the store still allows it: an open session would look recorded to its end.
RecordedSession begin_recorded_session(store::Store& store, const SessionStart& start,
                                       const std::vector<SessionLink>& links);
// Ends the session at `ended_wall_ns` and commits. Its recording should have ended first (SessionRecording::end).
void end_recorded_session(store::Store& store, std::int64_t session, std::int64_t ended_wall_ns);

}  // namespace imubridge::pipeline
