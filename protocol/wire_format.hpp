#pragma once
// The byte-stream formats a link can carry, by the names users type (--protocol, config files, the store).
#include <string_view>

namespace imubridge::protocol {

enum class WireFormat { imubridge, xbee, xbee_escaped, mavlink };

std::string_view wire_format_name(WireFormat format);
// Throws std::invalid_argument naming the valid formats.
WireFormat parse_wire_format(std::string_view name);

}  // namespace imubridge::protocol
