#include "daemon/mavlink_requests.hpp"

#include <array>
#include <bit>
#include <cmath>

namespace imubridge::daemon {

std::vector<std::uint8_t> set_message_interval(std::uint32_t msgid, double hz, std::uint8_t target_system,
                                               std::uint8_t target_component,
                                               const protocol::mavlink::FrameOptions& from) {
  // COMMAND_LONG on the wire (fields by size): param1..param7 (float), command (uint16), target_system,
  // target_component, confirmation (uint8): 33 bytes.
  std::array<std::uint8_t, 33> payload{};
  const auto put_float = [&](std::size_t at, float value) {
    const auto bits = std::bit_cast<std::uint32_t>(value);
    for (int i = 0; i < 4; ++i) payload[at + i] = static_cast<std::uint8_t>(bits >> (8 * i));
  };
  put_float(0, static_cast<float>(msgid));
  put_float(4, static_cast<float>(std::round(1e6 / hz)));
  payload[28] = static_cast<std::uint8_t>(kMavCmdSetMessageInterval & 0xFF);
  payload[29] = static_cast<std::uint8_t>(kMavCmdSetMessageInterval >> 8);
  payload[30] = target_system;
  payload[31] = target_component;
  std::vector<std::uint8_t> frame;
  protocol::mavlink::encode(protocol::mavlink::make_message(kCommandLongId, payload, from), frame);
  return frame;
}

}  // namespace imubridge::daemon
