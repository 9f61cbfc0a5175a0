#include "protocol/wire_format.hpp"

#include <array>
#include <stdexcept>
#include <string>
#include <utility>

namespace imubridge::protocol {
namespace {
constexpr std::array<std::pair<WireFormat, std::string_view>, 4> kNames{{
    {WireFormat::imubridge, "imubridge"},
    {WireFormat::xbee, "xbee"},
    {WireFormat::xbee_escaped, "xbee-escaped"},
    {WireFormat::mavlink, "mavlink"},
}};
}  // namespace

std::string_view wire_format_name(WireFormat format) {
  for (const auto& [f, name] : kNames) {
    if (f == format) return name;
  }
  return "unknown";
}

WireFormat parse_wire_format(std::string_view name) {
  for (const auto& [f, known] : kNames) {
    if (known == name) return f;
  }
  throw std::invalid_argument("unknown protocol '" + std::string(name) +
                              "' (valid: imubridge, xbee, xbee-escaped, mavlink)");
}

}  // namespace imubridge::protocol
