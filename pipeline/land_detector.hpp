#pragma once
// The autopilot's land detector, for the estimators (EstimationStage::set_landed: a zero-velocity update while the
// vehicle stands on the ground, docs/estimator.md "On the ground"). Two ways it reaches the pipeline: a MAVLink link
// carries it in its bytes (EXTENDED_SYS_STATE), which the engine reads, so live runs and replays of them see it at the
// same chunk; an imported log's detector (PX4's vehicle_land_detected) is stored as the session's `takeoff` and
// `landing` events, which replay applies at their time. A raw IMU link has none: its filter reads drag throughout.
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "pipeline/link_decoder.hpp"
#include "protocol/mavlink.hpp"
#include "store/records.hpp"

namespace imubridge::pipeline {

// What `m` says of its sender's landed state when it is an EXTENDED_SYS_STATE of the system of `imu` (the link's IMU:
// another vehicle's detector is not this IMU's): true on the ground; false in the air, taking off or landing
// (moving) and when the detector does not know (undefined: rest is never assumed). nullopt for any other message,
// and before the link knows its IMU.
std::optional<bool> mavlink_landed(const protocol::mavlink::Message& m,
                                   const std::optional<protocol::mavlink::ImuSource>& imu);

// One MAVLink link's land detector as it changes its mind: what the recording stores as takeoff and landing events and
// the daemon logs. The first state heard is where it starts, not a change.
class MavlinkLandDetectorChanges {
 public:
  struct Change {
    bool landed = false;
    std::uint8_t system = 0;  // the autopilot's
  };
  // The changes among `decoder`'s last messages (mavlink_landed: its IMU's system's), in order.
  std::vector<Change> after(const LinkDecoder& decoder);

 private:
  std::optional<bool> landed_;
};

// The land detector's `takeoff` and `landing` events among a session's `events`, in time order (stable where times
// tie).
std::vector<store::Event> land_detector_events(std::span<const store::Event> events);

// A session's stored land-detector events in time order, replayed against the chunks' receive times.
class StoredLandDetector {
 public:
  // Keeps the `takeoff` and `landing` events of `events` (a session's, any order).
  explicit StoredLandDetector(std::span<const store::Event> events);
  // Landed before the first event: the first is a takeoff. False without events (no detector: never assume rest).
  bool landed_at_start() const { return !events_.empty() && events_.front().kind == "takeoff"; }
  struct Change {
    std::optional<std::int64_t> link_id;  // the store link it belongs to; empty for the whole session
    bool landed = false;
  };
  // The changes at or before `mono_ns` not given before, in order.
  std::vector<Change> until(std::int64_t mono_ns);

 private:
  std::vector<store::Event> events_;
  std::size_t next_ = 0;
};

}  // namespace imubridge::pipeline
