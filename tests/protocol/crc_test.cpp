#include "protocol/crc.hpp"

#include <gtest/gtest.h>

#include <string_view>
#include <vector>

namespace imubridge::protocol {
namespace {

std::vector<std::uint8_t> bytes_of(std::string_view s) { return {s.begin(), s.end()}; }

TEST(Crc16Mcrf4xx, PublishedCheckValue) { EXPECT_EQ(crc16_mcrf4xx(bytes_of("123456789")), 0x6F91); }

TEST(Crc16Mcrf4xx, ContinuesAcrossSplits) {
  const auto data = bytes_of("imubridge streams IMU frames");
  const std::uint16_t whole = crc16_mcrf4xx(data);
  for (std::size_t split = 0; split <= data.size(); ++split) {
    std::span<const std::uint8_t> all(data);
    EXPECT_EQ(crc16_mcrf4xx(all.subspan(split), crc16_mcrf4xx(all.first(split))), whole) << "split " << split;
  }
}

TEST(Crc16Mcrf4xx, EmptyInputLeavesSeed) { EXPECT_EQ(crc16_mcrf4xx({}), kCrc16Init); }

}  // namespace
}  // namespace imubridge::protocol
