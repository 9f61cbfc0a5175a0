#include "pipeline/radio_link.hpp"

#include <algorithm>
#include <charconv>

#include "protocol/hex.hpp"

namespace imubridge::pipeline {
namespace {

constexpr std::size_t kAddressBytes = 8;  // XBee 64-bit source address

}  // namespace

std::string radio_link_name(std::string_view link, std::uint64_t source64) {
  return std::string(link) + "/" + protocol::hex(source64, kAddressBytes);
}

std::string radio_link_description(std::string_view link, std::uint64_t source64) {
  return "XBee radio " + protocol::hex(source64, kAddressBytes) + " via " + std::string(link);
}

std::optional<RadioLinkName> parse_radio_link_name(std::string_view name) {
  const auto slash = name.rfind('/');
  if (slash == std::string_view::npos || slash == 0) return std::nullopt;
  const std::string_view address = name.substr(slash + 1);
  // Exactly what protocol::hex() writes, so a name reads back only as the radio it was made for.
  const bool written_by_hex = address.size() == 2 * kAddressBytes &&
                              std::all_of(address.begin(), address.end(),
                                          [](char c) { return (c >= '0' && c <= '9') || (c >= 'A' && c <= 'F'); });
  if (!written_by_hex) return std::nullopt;
  RadioLinkName radio{.link = std::string(name.substr(0, slash))};
  std::from_chars(address.data(), address.data() + address.size(), radio.source64, 16);
  return radio;
}

}  // namespace imubridge::pipeline
