#pragma once
// An XBee radio heard through a link is a vehicle of its own: its samples carry a link id of their own, so no
// estimator mixes two vehicles. While recording, that id is a store link named "<link>/<SOURCE64>" (the radio's
// address as 16 upper-case hex digits), which replay reads back to find the link a radio was heard through. Link
// names never hold a '/' (daemon/config_file.cpp keeps them plain), so the two kinds of names cannot be confused.
// While not recording there is no store to give ids, and unrecorded_radio_id() makes ones no store link has.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "protocol/sample.hpp"

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

// The link id of the `radio_index`-th radio (in order of first appearance) heard through the `link_index`-th link,
// while not recording: bit 62 set, far above any store link's id (SQLite counts row ids up from 1); the link's index
// in bits 16-30, the radio's in bits 0-15.
protocol::LinkId unrecorded_radio_id(std::uint32_t link_index, std::uint32_t radio_index);
bool is_unrecorded_radio_id(protocol::LinkId id);
// The index of the link an unrecorded_radio_id() was heard through.
std::uint32_t unrecorded_radio_link_index(protocol::LinkId id);

}  // namespace imubridge::pipeline
