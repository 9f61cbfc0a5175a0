#include "protocol/crc.hpp"

#include <array>

namespace imubridge::protocol {
namespace {

constexpr const auto& kTable = detail::kCrc16Table;

// kSlices[k][b]: the CRC contribution of byte b followed by k zero bytes (from a zero register), so sixteen
// bytes fold into the register with sixteen independent lookups instead of a chain of sixteen.
constexpr std::size_t kSliceBytes = 16;
constexpr std::array<std::array<std::uint16_t, 256>, kSliceBytes> make_slices() {
  std::array<std::array<std::uint16_t, 256>, kSliceBytes> slices{};
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

// Folds the n bytes at p (2 <= n <= kSliceBytes) into the register in one step: byte k enters through kSlices[n - 1 -
// k]. The 16-bit register overlaps the first two bytes only; the others enter with no register bits.
std::uint16_t fold(const std::uint8_t* p, std::size_t n, std::uint16_t crc) noexcept {
  auto folded = static_cast<std::uint16_t>(kSlices[n - 1][static_cast<std::uint8_t>(p[0] ^ (crc & 0xFFu))] ^
                                           kSlices[n - 2][static_cast<std::uint8_t>(p[1] ^ (crc >> 8))]);
  for (std::size_t k = 2; k < n; ++k) folded ^= kSlices[n - 1 - k][p[k]];
  return folded;
}

}  // namespace

std::uint16_t crc16_mcrf4xx(std::span<const std::uint8_t> data, std::uint16_t crc) noexcept {
  for (std::uint8_t byte : data) crc = crc16_mcrf4xx_update(crc, byte);
  return crc;
}

std::uint16_t crc16_mcrf4xx_fast(std::span<const std::uint8_t> data, std::uint16_t crc) noexcept {
  const std::uint8_t* p = data.data();
  std::size_t n = data.size();
  for (; n >= kSliceBytes; p += kSliceBytes, n -= kSliceBytes) crc = fold(p, kSliceBytes, crc);
  // The last 2..15 bytes in one more step too, rather than a chain of byte-wise steps (a MAVLink frame's CRC covers a
  // length that is rarely a multiple of 16, and that chain took about half the time of the whole CRC).
  if (n >= 2) return fold(p, n, crc);
  return n == 1 ? crc16_mcrf4xx_update(crc, p[0]) : crc;
}

}  // namespace imubridge::protocol
