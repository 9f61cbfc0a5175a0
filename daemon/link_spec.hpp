#pragma once
// The --link shorthand of `imubridge run`: a link given on the command line, and how it combines with the links of
// the configuration file (docs/config.md).
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "daemon/config.hpp"

namespace imubridge::daemon {

// A link given on the command line: "NAME=DEVICE:PROTOCOL[:BAUD]". DEVICE is a path, or "usb:VID:PID[:SERIAL]" with
// VID and PID in hex.
struct LinkSpec {
  std::string name;
  DeviceSelector device;
  protocol::WireFormat format = protocol::WireFormat::imubridge;
  std::optional<std::uint32_t> baud;
};
// Throws std::invalid_argument naming the spec and what is wrong with it.
LinkSpec parse_link_spec(std::string_view spec);
// Command-line links take precedence: a link of the same name keeps its other settings (bridge, calibration, ...)
// and takes the spec's device, protocol and baud (if given); a new name adds a link with default settings.
void apply_link_spec(Config& config, const LinkSpec& spec);

}  // namespace imubridge::daemon
