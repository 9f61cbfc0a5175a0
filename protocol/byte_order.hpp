#pragma once
// Little-endian fields, as imubridge frames and MAVLink carry them. Any 1-, 2-, 4- or 8-byte arithmetic type (floats
// included) moves through the unsigned integer of its size.
#include <bit>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>
#include <vector>

namespace imubridge::protocol {

template <typename T>
concept WireScalar = std::is_arithmetic_v<T> &&(sizeof(T) == 1 || sizeof(T) == 2 || sizeof(T) == 4 || sizeof(T) == 8);

template <WireScalar T>
using UnsignedOfSize =
    std::conditional_t<sizeof(T) == 1, std::uint8_t,
                       std::conditional_t<sizeof(T) == 2, std::uint16_t,
                                          std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>>>;

template <WireScalar T>
T load_le(const std::uint8_t* p) {
  UnsignedOfSize<T> bits = 0;
  if constexpr (std::endian::native == std::endian::little) {
    std::memcpy(&bits, p, sizeof bits);  // one load: GCC does not merge the byte loop below into one
  } else {
    for (std::size_t i = 0; i < sizeof bits; ++i) bits |= static_cast<decltype(bits)>(decltype(bits){p[i]} << (8 * i));
  }
  return std::bit_cast<T>(bits);
}

template <WireScalar T>
void store_le(std::uint8_t* p, T value) {
  const auto bits = std::bit_cast<UnsignedOfSize<T>>(value);
  if constexpr (std::endian::native == std::endian::little) {
    std::memcpy(p, &bits, sizeof bits);
  } else {
    for (std::size_t i = 0; i < sizeof bits; ++i) p[i] = static_cast<std::uint8_t>(bits >> (8 * i));
  }
}

template <WireScalar T>
void append_le(std::vector<std::uint8_t>& out, T value) {
  out.resize(out.size() + sizeof value);
  store_le(out.data() + out.size() - sizeof value, value);
}

}  // namespace imubridge::protocol
