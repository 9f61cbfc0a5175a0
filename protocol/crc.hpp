#pragma once
// CRC-16/MCRF4XX (the "X.25" CRC that MAVLink uses): reflected polynomial 0x1021 (0x8408), init 0xFFFF,
// no final XOR. Check value over "123456789" is 0x6F91. imubridge frames use the same CRC, so one table
// serves both protocols and the decode benchmarks compare against one reference pass.
#include <array>
#include <cstdint>
#include <span>

namespace imubridge::protocol {

inline constexpr std::uint16_t kCrc16Init = 0xFFFF;

namespace detail {
constexpr std::array<std::uint16_t, 256> make_crc16_table() {
  std::array<std::uint16_t, 256> table{};
  for (unsigned i = 0; i < 256; ++i) {
    std::uint16_t crc = static_cast<std::uint16_t>(i);
    for (int bit = 0; bit < 8; ++bit) crc = (crc & 1u) ? static_cast<std::uint16_t>((crc >> 1) ^ 0x8408u) : crc >> 1;
    table[i] = crc;
  }
  return table;
}
inline constexpr auto kCrc16Table = make_crc16_table();
}  // namespace detail

// One byte through the CRC, table-driven. Inline: a MAVLink frame's CRC ends with one byte more (its CRC_EXTRA), and a
// call for it took a twentieth of the decoding time.
inline std::uint16_t crc16_mcrf4xx_update(std::uint16_t crc, std::uint8_t byte) noexcept {
  return static_cast<std::uint16_t>((crc >> 8) ^ detail::kCrc16Table[(crc ^ byte) & 0xFFu]);
}

// The CRC of `data`, continuing from `crc` (pass kCrc16Init to start).
std::uint16_t crc16_mcrf4xx(std::span<const std::uint8_t> data, std::uint16_t crc = kCrc16Init) noexcept;

// The same CRC, sixteen bytes per step (slicing-by-16): what decoders use on their hot path. The byte-wise
// functions above stay as the reference that benchmarks measure decoders against.
std::uint16_t crc16_mcrf4xx_fast(std::span<const std::uint8_t> data, std::uint16_t crc = kCrc16Init) noexcept;

}  // namespace imubridge::protocol
