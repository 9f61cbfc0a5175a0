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

// kSlices[k][b]: the CRC contribution of byte b followed by k zero bytes (from a zero register), so eight
// bytes fold into the register with eight independent lookups instead of a chain of eight.
constexpr std::array<std::array<std::uint16_t, 256>, 8> make_slices() {
  std::array<std::array<std::uint16_t, 256>, 8> slices{};
  slices[0] = kTable;
  for (std::size_t k = 1; k < slices.size(); ++k) {
    for (unsigned i = 0; i < 256; ++i) {
      const std::uint16_t prev = slices[k - 1][i];
      slices[k][i] = static_cast<std::uint16_t>((prev >> 8) ^ kTable[prev & 0xFFu]);
    }
  }
  return slices;
}
constexpr auto kSlices = make_slices();

}  // namespace

std::uint16_t crc16_mcrf4xx_update(std::uint16_t crc, std::uint8_t byte) noexcept {
  return static_cast<std::uint16_t>((crc >> 8) ^ kTable[(crc ^ byte) & 0xFFu]);
}

std::uint16_t crc16_mcrf4xx(std::span<const std::uint8_t> data, std::uint16_t crc) noexcept {
  for (std::uint8_t byte : data) crc = crc16_mcrf4xx_update(crc, byte);
  return crc;
}

std::uint16_t crc16_mcrf4xx_fast(std::span<const std::uint8_t> data, std::uint16_t crc) noexcept {
  const std::uint8_t* p = data.data();
  std::size_t n = data.size();
  for (; n >= 8; p += 8, n -= 8) {
    // The 16-bit register overlaps the first two bytes only; the other six enter with no register bits.
    const auto b0 = static_cast<std::uint8_t>(p[0] ^ (crc & 0xFFu));
    const auto b1 = static_cast<std::uint8_t>(p[1] ^ (crc >> 8));
    crc = static_cast<std::uint16_t>(kSlices[7][b0] ^ kSlices[6][b1] ^ kSlices[5][p[2]] ^ kSlices[4][p[3]] ^
                                     kSlices[3][p[4]] ^ kSlices[2][p[5]] ^ kSlices[1][p[6]] ^ kSlices[0][p[7]]);
  }
  return crc16_mcrf4xx(data.last(n), crc);
}

}  // namespace imubridge::protocol
