#include "protocol/hex.hpp"

#include <charconv>
#include <stdexcept>

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

std::uint64_t parse_hex(std::string_view text, int max_digits) {
  std::uint64_t value = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value, 16);
  if (text.empty() || text.size() > static_cast<std::size_t>(max_digits) || ec != std::errc() ||
      end != text.data() + text.size()) {
    throw std::invalid_argument("'" + std::string(text) + "' is not a hex number of at most " +
                                std::to_string(max_digits) + " digits");
  }
  return value;
}

}  // namespace imubridge::protocol
