#pragma once
// An XBee radio heard through a link is a vehicle of its own: its samples are keyed by the link and the radio's address
// (protocol::SourceKey), so no estimator mixes two vehicles. A recording stores them under a store link of their own
// named "<link>/<SOURCE64>" (the address as 16 upper-case hex digits), which replay reads back to find the radio's
// link. Link names never hold a '/' (daemon/config_file.cpp keeps them plain), so the two kinds of names cannot be
// confused.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace imubridge::pipeline {

// The store link of radio `source64` heard through link `link`: "<link>/<SOURCE64>".
std::string radio_link_name(std::string_view link, std::uint64_t source64);
// That store link's description, for people: "XBee radio <SOURCE64> via <link>".
std::string radio_link_description(std::string_view link, std::uint64_t source64);

struct RadioLinkName {
  std::string link;  // the link the radio was heard through
  std::uint64_t source64 = 0;

  friend bool operator==(const RadioLinkName&, const RadioLinkName&) = default;
};
// radio_link_name() read back; nullopt for any other name.
std::optional<RadioLinkName> parse_radio_link_name(std::string_view name);

}  // namespace imubridge::pipeline
