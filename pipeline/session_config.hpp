#pragma once
// What a session must remember to be decoded again: for each recorded link, its wire format and the calibration
// that turned its counts into SI values. Every writer of sessions (the daemon, the simulator, imports) puts this
// under "links" in the session's config snapshot, and replay reads it back from there.
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "pipeline/link_decoder.hpp"
#include "protocol/calibration.hpp"
#include "protocol/mavlink.hpp"
#include "protocol/wire_format.hpp"

namespace imubridge::pipeline {

struct RecordedLink {
  std::string name;  // the store link's name
  protocol::WireFormat format = protocol::WireFormat::imubridge;
  protocol::Calibration calibration = protocol::Calibration::reference_board();
  // How the IMU's axes sit in the body (estimator::parse_imu_axes spelling). Sessions recorded before it was kept
  // read back as "auto": detect from gravity.
  std::string imu_axes = "auto";
  // A MAVLink link's one IMU (LinkDecoder): set by imports of MAVLink logs, where several IMUs may be present.
  // Absent: every IMU message gives samples, as on a live link.
  std::optional<protocol::mavlink::ImuSource> mavlink_imu{};
  // A live MAVLink link's: keep to the first IMU heard that this admits (LinkDecoder::lock_mavlink_imu), at
  // recording and on every replay.
  std::optional<MavlinkImuLock> mavlink_imu_lock{};
};

// The decoder that reads `link`'s bytes as it was recorded: its format, calibration, and MAVLink IMU or lock.
LinkDecoder make_decoder(const RecordedLink& link);

nlohmann::json calibration_to_json(const protocol::Calibration& c);
// Throws std::invalid_argument naming the bad field.
protocol::Calibration calibration_from_json(const nlohmann::json& j);

// {"links": [{"name": .., "protocol": .., "calibration": {..}, "imu_axes": .., "mavlink_imu": {"message": ..,
// "msgid": .., "sysid": .., "compid": .., "id": ..} when set, "mavlink_imu_lock": {"message": .., "msgid": .., "id":
// .., each only when set} when set},
// ...]} merged into `config`.
void add_recorded_links(nlohmann::json& config, const std::vector<RecordedLink>& links);
// Throws std::invalid_argument when the snapshot has no usable "links".
std::vector<RecordedLink> recorded_links(const std::string& session_config_json);

}  // namespace imubridge::pipeline
