#include "daemon/link_spec.hpp"

#include <algorithm>
#include <charconv>
#include <stdexcept>
#include <vector>

#include "daemon/config_file.hpp"
#include "protocol/hex.hpp"

namespace imubridge::daemon {
namespace {

bool is_wire_format(std::string_view text) {
  try {
    protocol::parse_wire_format(text);
    return true;
  } catch (const std::invalid_argument&) {
    return false;
  }
}

}  // namespace

LinkSpec parse_link_spec(std::string_view spec) {
  const auto fail = [spec](const std::string& what) {
    return std::invalid_argument("--link '" + std::string(spec) + "': " + what +
                                 " (expected NAME=DEVICE:PROTOCOL[:BAUD], DEVICE a path or usb:VID:PID[:SERIAL])");
  };
  const auto equals = spec.find('=');
  if (equals == std::string_view::npos || equals == 0) throw fail("no NAME=");
  LinkSpec link;
  link.name = spec.substr(0, equals);
  std::vector<std::string_view> fields;  // DEVICE may hold colons itself: read PROTOCOL and BAUD from the right
  for (std::string_view rest = spec.substr(equals + 1);;) {
    const auto colon = rest.find(':');
    fields.push_back(rest.substr(0, colon));
    if (colon == std::string_view::npos) break;
    rest = rest.substr(colon + 1);
  }
  // The last field is BAUD when it is not a protocol but the one before is, or when it is all digits: so "-5" or
  // "1e8" after a protocol is a bad baud rate, not an unknown protocol.
  const std::string_view last = fields.back();
  const bool all_digits =
      !last.empty() && std::all_of(last.begin(), last.end(), [](char c) { return c >= '0' && c <= '9'; });
  if (fields.size() >= 3 && !is_wire_format(last) && (all_digits || is_wire_format(fields[fields.size() - 2]))) {
    std::int64_t baud = 0;
    const auto [end, ec] = std::from_chars(last.data(), last.data() + last.size(), baud);
    if (last.empty() || ec != std::errc() || end != last.data() + last.size()) {
      throw fail("baud rate '" + std::string(last) + "' is not a whole number");
    }
    try {
      check_baud(baud);
    } catch (const std::invalid_argument& e) {
      throw fail(e.what());
    }
    link.baud = static_cast<std::uint32_t>(baud);
    fields.pop_back();
  }
  if (fields.size() < 2) throw fail("no PROTOCOL");
  try {
    link.format = protocol::parse_wire_format(fields.back());
  } catch (const std::invalid_argument& e) {
    throw fail(e.what());
  }
  fields.pop_back();
  if (fields.front() == "usb") {
    if (fields.size() != 3 && fields.size() != 4) throw fail("usb:VID:PID[:SERIAL] expected");
    try {
      link.device.usb_vid = static_cast<std::uint16_t>(protocol::parse_hex(fields[1], 4));
      link.device.usb_pid = static_cast<std::uint16_t>(protocol::parse_hex(fields[2], 4));
    } catch (const std::invalid_argument& e) {
      throw fail(e.what());
    }
    if (fields.size() == 4) link.device.usb_serial = std::string(fields[3]);
  } else {
    std::string path;
    for (const auto& f : fields) path += (path.empty() ? "" : ":") + std::string(f);
    if (path.empty()) throw fail("no DEVICE");
    link.device.path = path;
  }
  return link;
}

void apply_link_spec(Config& config, const LinkSpec& spec) {
  auto it =
      std::find_if(config.links.begin(), config.links.end(), [&](const LinkConfig& l) { return l.name == spec.name; });
  if (it == config.links.end()) {
    it = config.links.emplace(config.links.end());
    it->name = spec.name;
  }
  it->device = spec.device;
  it->format = spec.format;
  if (spec.baud) it->baud = *spec.baud;
}

}  // namespace imubridge::daemon
