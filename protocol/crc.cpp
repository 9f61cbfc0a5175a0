#include "protocol/crc.hpp"

#include <array>

namespace imubridge::protocol {
namespace {

constexpr std::array<std::uint16_t, 256> make_table() {
  std::array<std::uint16_t, 256> table{};
  for (unsigned i = 0; i < 256; ++i) {
    std::uint16_t crc = static_cast<std::uint16_t>(i);
    for (int bit = 0; bit < 8; ++bit) crc = (crc & 1u) ? static_cast<std::uint16_t>((crc >> 1) ^ 0x8408u) : crc >> 1;
    table[i] = crc;
  }
  return table;
}
constexpr auto kTable = make_table();

}  // namespace

std::uint16_t crc16_mcrf4xx_update(std::uint16_t crc, std::uint8_t byte) noexcept {
  return static_cast<std::uint16_t>((crc >> 8) ^ kTable[(crc ^ byte) & 0xFFu]);
}

std::uint16_t crc16_mcrf4xx(std::span<const std::uint8_t> data, std::uint16_t crc) noexcept {
  for (std::uint8_t byte : data) crc = crc16_mcrf4xx_update(crc, byte);
  return crc;
}

}  // namespace imubridge::protocol
