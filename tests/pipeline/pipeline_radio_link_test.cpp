// The XBee radio -> store link rule the recording and replay share: the store link's name.
#include <gtest/gtest.h>

#include <cstdint>
#include <optional>

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

}  // namespace
}  // namespace imubridge::pipeline
