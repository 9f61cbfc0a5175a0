#include "protocol/hex.hpp"

namespace imubridge::protocol {
namespace {

void append_hex(std::string& s, std::uint8_t byte) {
  static constexpr char kDigits[] = "0123456789ABCDEF";
  s += {kDigits[byte >> 4], kDigits[byte & 0xF]};
}

}  // namespace

std::string hex(std::span<const std::uint8_t> bytes) {
  std::string s;
  s.reserve(2 * bytes.size());
  for (std::uint8_t b : bytes) append_hex(s, b);
  return s;
}

std::string hex(std::uint64_t value, std::size_t bytes) {
  std::string s;
  s.reserve(2 * bytes);
  for (std::size_t i = bytes; i-- > 0;) append_hex(s, static_cast<std::uint8_t>(value >> (8 * i)));
  return s;
}

}  // namespace imubridge::protocol
