#pragma once
// Upper-case hex: how JSON output shows byte strings and radio addresses.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

namespace imubridge::protocol {

// {0x01, 0xAB} -> "01AB"
std::string hex(std::span<const std::uint8_t> bytes);

// The low `bytes` (at most 8) bytes of `value`, most significant first: hex(0x7D84, 2) -> "7D84".
std::string hex(std::uint64_t value, std::size_t bytes);

}  // namespace imubridge::protocol
