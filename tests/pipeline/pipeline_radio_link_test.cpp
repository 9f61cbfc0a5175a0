// The XBee radio -> link rule the recorder, replay and the daemon share: store link names and ids while not
// recording.
#include <gtest/gtest.h>

#include <cstdint>
#include <optional>
#include <set>

#include "pipeline/radio_link.hpp"

namespace imubridge::pipeline {
namespace {

TEST(RadioLink, NameIsTheLinkAndTheAddressInHex) {
  EXPECT_EQ(radio_link_name("radio", 0x0013A20040A1B2C3), "radio/0013A20040A1B2C3");
  EXPECT_EQ(radio_link_name("gcs-1.b", 0x42), "gcs-1.b/0000000000000042");
  EXPECT_EQ(radio_link_description("radio", 0x0013A20040A1B2C3), "XBee radio 0013A20040A1B2C3 via radio");
}

TEST(RadioLink, NameReadsBackAsTheLinkAndRadio) {
  for (const std::uint64_t source64 : {std::uint64_t{0}, std::uint64_t{0x0013A20040A1B2C3}, ~std::uint64_t{0}}) {
    EXPECT_EQ(parse_radio_link_name(radio_link_name("radio", source64)),
              (RadioLinkName{.link = "radio", .source64 = source64}));
  }
}

TEST(RadioLink, OtherNamesAreNotRadios) {
  EXPECT_EQ(parse_radio_link_name("radio"), std::nullopt);  // a port link
  EXPECT_EQ(parse_radio_link_name("/0013A20040A1B2C3"), std::nullopt);
  EXPECT_EQ(parse_radio_link_name("radio/"), std::nullopt);
  EXPECT_EQ(parse_radio_link_name("radio/0013A20040A1B2C"), std::nullopt);    // 15 digits
  EXPECT_EQ(parse_radio_link_name("radio/0013A20040A1B2C30"), std::nullopt);  // 17
  EXPECT_EQ(parse_radio_link_name("radio/0013a20040a1b2c3"), std::nullopt);   // hex() writes upper case
  EXPECT_EQ(parse_radio_link_name("radio/0013A20040A1B2G3"), std::nullopt);
}

TEST(RadioLink, UnrecordedIdsAreAboveStoreIdsAndNameTheirLink) {
  std::set<protocol::LinkId> ids;
  for (std::uint32_t link = 0; link < 3; ++link) {
    for (std::uint32_t radio = 0; radio < 3; ++radio) {
      const protocol::LinkId id = unrecorded_radio_id(link, radio);
      EXPECT_TRUE(is_unrecorded_radio_id(id));
      EXPECT_GE(id, protocol::LinkId{1} << 62);
      EXPECT_EQ(unrecorded_radio_link_index(id), link);
      ids.insert(id);
    }
  }
  EXPECT_EQ(ids.size(), 9u) << "every radio of every link has an id of its own";
  EXPECT_EQ(unrecorded_radio_id(2, 5), (protocol::LinkId{1} << 62) + 0x20005);
  EXPECT_FALSE(is_unrecorded_radio_id(1));  // store link ids (SQLite row ids) stay far below
  EXPECT_FALSE(is_unrecorded_radio_id(std::int64_t{1} << 40));
}

}  // namespace
}  // namespace imubridge::pipeline
