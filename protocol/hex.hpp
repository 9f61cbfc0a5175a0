#pragma once
// Upper-case hex: how JSON output shows byte strings and radio addresses; and hex numbers people write.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

namespace imubridge::protocol {

// {0x01, 0xAB} -> "01AB"
std::string hex(std::span<const std::uint8_t> bytes);

// The low `bytes` (at most 8) bytes of `value`, most significant first: hex(0x7D84, 2) -> "7D84".
std::string hex(std::uint64_t value, std::size_t bytes);

// A hex number of 1 to `max_digits` digits, either case, nothing else: parse_hex("0403", 4) -> 0x0403. Throws
// std::invalid_argument "'<text>' is not a hex number of at most <max_digits> digits".
std::uint64_t parse_hex(std::string_view text, int max_digits);

}  // namespace imubridge::protocol
