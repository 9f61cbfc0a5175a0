#pragma once
// What a MAVLink link asks of the vehicle: each configured message at its rate (`request_rates`), as COMMAND_LONG
// MAV_CMD_SET_MESSAGE_INTERVAL frames from the ground station (docs/protocol.md, "A live MAVLink link").
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "protocol/mavlink.hpp"

namespace imubridge::daemon {

constexpr std::uint16_t kMavCmdSetMessageInterval = 511;
constexpr std::uint32_t kCommandLongId = 76;

// One COMMAND_LONG frame (MAVLink 2) asking `target_system`/`target_component` (0: every system/component) to send
// message `msgid` every 1e6 / hz microseconds: param1 the id, param2 the interval in µs.
std::vector<std::uint8_t> set_message_interval(std::uint32_t msgid, double hz, std::uint8_t target_system,
                                               std::uint8_t target_component,
                                               const protocol::mavlink::FrameOptions& from);

}  // namespace imubridge::daemon
