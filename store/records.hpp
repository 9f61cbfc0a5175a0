#pragma once
// The rows of a session store as plain values: what writers hand to Store and readers get back. Samples travel as
// protocol::Sample. docs/storage.md maps every field to its column. Every member has an initializer so that
// designated initializers may leave any of them out without -Wmissing-field-initializers.
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "store/process_identity.hpp"

namespace imubridge::store {

struct SessionInfo {
  std::string kind{};    // "live", "sim", "import", ...
  std::string source{};  // for people: "/dev/ttyUSB0 @ 921600 baud", "sim seed 7", an imported file's name
  std::string config{};  // snapshot of the configuration that produced the session (text: TOML or JSON)
  std::int64_t started_wall_ns = 0;
  std::string software_version = IMUBRIDGE_VERSION;  // set it only when importing another build's data
  friend bool operator==(const SessionInfo&, const SessionInfo&) = default;
};

struct Session {
  std::int64_t id = 0;
  SessionInfo info{};
  // Empty while recording, or while its writer's death is not yet noticed (Store::end_interrupted_sessions).
  std::optional<std::int64_t> ended_wall_ns{};
  // The ending is the last stored time of a writer that died without ending the session.
  bool interrupted = false;
  std::optional<ProcessIdentity> writer{};  // the process that began it; empty in files of schema version 1
  friend bool operator==(const Session&, const Session&) = default;
};

// "ended", "interrupted" (its writer died; ended at its last stored time) or "open" (being written, or written by a
// process this file cannot tell is gone).
inline const char* state_name(const Session& session) {
  if (!session.ended_wall_ns) return "open";
  return session.interrupted ? "interrupted" : "ended";
}

struct Link {
  std::int64_t id = 0;
  std::int64_t session_id = 0;
  std::string name{};      // the configuration's name for it: "imu0"
  std::string protocol{};  // "imubridge", "xbee", "mavlink"
  std::string device{};    // "/dev/ttyUSB0 @ 921600 baud, FTDI FT232R serial A50285BI"
  friend bool operator==(const Link&, const Link&) = default;
};

enum class Direction { rx, tx };  // rx: from the vehicle to us; tx: from us to the vehicle

// Bytes exactly as one read() returned them (or one write() sent them): replay's ground truth.
struct Chunk {
  std::int64_t link_id = 0;
  Direction direction = Direction::rx;
  std::int64_t recv_mono_ns = 0;
  std::int64_t recv_wall_ns = 0;
  std::vector<std::uint8_t> bytes{};
  friend bool operator==(const Chunk&, const Chunk&) = default;
};

struct Event {
  std::optional<std::int64_t> link_id{};  // empty for events of the whole session
  std::int64_t mono_ns = 0;
  std::int64_t wall_ns = 0;
  std::string kind{};  // "sequence_gap", "crc_failure", "reconnect", "link_lost", "note", "counters", ...
  std::int64_t count = 1;
  std::string detail{};  // free text, or JSON (the DecoderCounters of a "counters" event)
  friend bool operator==(const Event&, const Event&) = default;
};

struct RunInfo {
  std::string kind{};         // "live" or "replay"
  std::string params_json{};  // the model parameters and options the run used
  std::int64_t created_wall_ns = 0;
  std::string software_version = IMUBRIDGE_VERSION;
  friend bool operator==(const RunInfo&, const RunInfo&) = default;
};

struct Run {
  std::int64_t id = 0;
  std::int64_t session_id = 0;
  RunInfo info{};
  friend bool operator==(const Run&, const Run&) = default;
};

// One output of the velocity estimator for one sample.
struct Estimate {
  std::int64_t link_id = 0;
  std::uint64_t seq = 0;  // the sample's sequence number
  double t_s = 0;
  double fx = 0, fy = 0;  // compensated specific force, m/s^2
  double vx = 0, vy = 0;  // velocity, m/s
  double var_vx = 0, var_vy = 0;
  friend bool operator==(const Estimate&, const Estimate&) = default;
};

// Where the vehicle really was (motion capture, or a simulator's truth): never mixed with measurements.
struct ReferenceRow {
  std::int64_t t_ns = 0;
  std::array<double, 3> position{};                 // m
  std::array<double, 4> quat_wxyz{};                // attitude, unit quaternion
  std::optional<std::array<double, 3>> velocity{};  // m/s, when the source has it
  friend bool operator==(const ReferenceRow&, const ReferenceRow&) = default;
};

}  // namespace imubridge::store
