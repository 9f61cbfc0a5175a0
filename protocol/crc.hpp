#pragma once
// CRC-16/MCRF4XX (the "X.25" CRC that MAVLink uses): reflected polynomial 0x1021 (0x8408), init 0xFFFF,
// no final XOR. Check value over "123456789" is 0x6F91. imubridge frames use the same CRC, so one table
// serves both protocols and the decode benchmarks compare against one reference pass.
#include <cstdint>
#include <span>

namespace imubridge::protocol {

inline constexpr std::uint16_t kCrc16Init = 0xFFFF;

// One byte through the CRC, table-driven.
std::uint16_t crc16_mcrf4xx_update(std::uint16_t crc, std::uint8_t byte) noexcept;

// The CRC of `data`, continuing from `crc` (pass kCrc16Init to start).
std::uint16_t crc16_mcrf4xx(std::span<const std::uint8_t> data, std::uint16_t crc = kCrc16Init) noexcept;

// The same CRC, eight bytes per step (slicing-by-8): what decoders use on their hot path. The byte-wise
// functions above stay as the reference that benchmarks measure decoders against.
std::uint16_t crc16_mcrf4xx_fast(std::span<const std::uint8_t> data, std::uint16_t crc = kCrc16Init) noexcept;

}  // namespace imubridge::protocol
