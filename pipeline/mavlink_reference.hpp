#pragma once
// A MAVLink sender's trajectory as reference rows (store::ReferenceRow): each LOCAL_POSITION_NED (position and
// velocity, NED) at the time its frame was received, on the session's clock (the chunk's receive time, the clock the
// samples carry, which identify and diagnose match reference rows against), with the attitude of the same sender
// from ATTITUDE_QUATERNION (or ATTITUDE, roll/pitch/yaw turned into that quaternion, when it sends no
// ATTITUDE_QUATERNION) on the autopilot's clock (time_boot_ms): equal, or slerped between the two bracketing
// attitudes at most 0.5 s apart, never across a restart. Messages are taken as they arrive; a position waits for the
// first attitude at or after it. `imubridge import tlog` and a live MAVLink link (LinkRecorder) both build their
// reference with it.
#include <Eigen/Geometry>
#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "protocol/mavlink.hpp"
#include "store/records.hpp"

namespace imubridge::pipeline {

// Whose positions and which attitude message: when not given, the sender is the first that sends a
// LOCAL_POSITION_NED (or the one prefer_sender named before that), and the attitude is ATTITUDE_QUATERNION once
// the sender has sent one, ATTITUDE until then.
struct MavlinkReferenceChoice {
  std::optional<std::pair<std::uint8_t, std::uint8_t>> sender{};  // system id, component id
  std::optional<bool> quaternions{};
};

class MavlinkReference {
 public:
  using Component = std::pair<std::uint8_t, std::uint8_t>;  // system id, component id

  using Choice = MavlinkReferenceChoice;
  explicit MavlinkReference(Choice choice = {}) : choice_(choice) {}

  // Without a chosen sender, the one to take positions from when its first one comes (the IMU's sender).
  void prefer_sender(Component sender) {
    if (!choice_.sender) preferred_ = sender;
  }
  // One decoded message received at `t_ns`; appends the rows it completes.
  void on_message(const protocol::mavlink::Message& m, std::int64_t t_ns, std::vector<store::ReferenceRow>& rows);
  // End of the stream: positions still waiting for an attitude after them are skipped.
  void finish(std::vector<store::ReferenceRow>& rows);

  // Rows left out, by reason ("no attitude around it", "position not a finite number", "timestamp not after the
  // previous row's", "attitude quaternion not of unit length", "attitude time not after the previous one's").
  std::map<std::string, std::uint64_t> skipped() const;
  std::uint64_t rows() const { return rows_; }
  // "LOCAL_POSITION_NED + ATTITUDE from system 1, component 1"; empty before the sender is known (or chosen).
  std::string source() const;

 private:
  struct Attitude {
    std::uint32_t epoch = 0;
    std::uint64_t device_us = 0;
    Eigen::Quaterniond q;
    auto key() const { return std::pair(epoch, device_us); }
  };
  struct Position {
    std::uint32_t epoch = 0;
    std::uint64_t device_us = 0;
    std::int64_t t_ns = 0;
    std::array<double, 3> position{}, velocity{};
    auto key() const { return std::pair(epoch, device_us); }
  };

  struct Attitudes {
    std::deque<Attitude> quaternions, eulers;  // ATTITUDE_QUATERNION, ATTITUDE
    std::map<std::string, std::uint64_t> skipped;
  };

  void add_attitude(Attitudes& to, bool quaternion, Attitude a);
  const std::deque<Attitude>& attitudes() const;
  // Resolves the waiting positions an attitude at or after them has come for (all of them at the end).
  void resolve(std::vector<store::ReferenceRow>& rows, bool at_end);
  void resolve_one(const Position& p, std::vector<store::ReferenceRow>& rows);

  Choice choice_;
  std::optional<Component> preferred_;
  std::optional<Component> sender_;
  // Every sender's attitudes until the sender is known (its first position may come after its first attitude).
  std::map<Component, Attitudes> attitudes_;
  std::deque<Position> waiting_;
  std::optional<std::int64_t> last_row_t_ns_;
  std::map<std::string, std::uint64_t> skipped_;
  std::uint64_t rows_ = 0;
};

}  // namespace imubridge::pipeline
