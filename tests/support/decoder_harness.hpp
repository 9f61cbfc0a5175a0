#pragma once
// What the decoder tests and fuzz targets share: decoding a stream in pieces through a whole decoder life (feed ...
// finish), and a CRC written from its definition, independent of protocol/crc.cpp. No GoogleTest in here, so the
// fuzz targets can use it too.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <nlohmann/json.hpp>
#include <optional>
#include <ostream>
#include <span>
#include <utility>
#include <vector>

#include "protocol/decoder_counters.hpp"

namespace imubridge::protocol {

// Lets GoogleTest print counters readably (found by argument-dependent lookup).
inline void PrintTo(const DecoderCounters& c, std::ostream* os) { *os << nlohmann::json(c).dump(); }

namespace harness {

template <typename D, typename Frame>
Frame frame_of(void (D::*)(std::vector<Frame>&));
// What a decoder emits: every decoder's finish() takes the vector its feed() appends to.
template <typename Decoder>
using FrameOf = decltype(frame_of(&Decoder::finish));

template <typename Decoder>
struct Decoded {
  std::vector<FrameOf<Decoder>> frames;
  DecoderCounters counters;  // after finish()
};

// Feeds `pieces` to `decoder` in order, then finishes.
template <typename Decoder>
Decoded<Decoder> decode_pieces(Decoder decoder, std::initializer_list<std::span<const std::uint8_t>> pieces) {
  Decoded<Decoder> d;
  for (const auto piece : pieces) decoder.feed(piece, d.frames);
  decoder.finish(d.frames);
  d.counters = decoder.counters();
  return d;
}

// The stream cut in two at `split`.
template <typename Decoder>
Decoded<Decoder> decode_split(Decoder decoder, std::span<const std::uint8_t> stream, std::size_t split) {
  return decode_pieces(std::move(decoder), {stream.first(split), stream.subspan(split)});
}

// The first point at which cutting the stream in two changes the frames or the counters from `whole`'s, if any.
template <typename Decoder>
std::optional<std::size_t> first_split_that_differs(const Decoder& fresh, std::span<const std::uint8_t> stream,
                                                    const Decoded<Decoder>& whole) {
  for (std::size_t split = 0; split <= stream.size(); ++split) {
    const Decoded<Decoder> d = decode_split(fresh, stream, split);
    if (d.frames != whole.frames || d.counters != whole.counters) return split;
  }
  return std::nullopt;
}

// The stream in pieces of `chunk` bytes (0: all at once).
template <typename Decoder>
Decoded<Decoder> decode_chunked(Decoder decoder, std::span<const std::uint8_t> stream, std::size_t chunk = 0) {
  Decoded<Decoder> d;
  if (chunk == 0) chunk = std::max<std::size_t>(stream.size(), 1);
  for (std::size_t at = 0; at < stream.size(); at += chunk) {
    decoder.feed(stream.subspan(at, std::min(chunk, stream.size() - at)), d.frames);
  }
  decoder.finish(d.frames);
  d.counters = decoder.counters();
  return d;
}

// CRC-16/MCRF4XX bit by bit, straight from its definition (reflected polynomial 0x1021, initial value 0xFFFF).
inline std::uint16_t crc_bit_serial(std::span<const std::uint8_t> data) {
  std::uint16_t crc = 0xFFFF;
  for (std::uint8_t byte : data) {
    crc ^= byte;
    for (int bit = 0; bit < 8; ++bit) crc = (crc & 1) ? (crc >> 1) ^ 0x8408 : crc >> 1;
  }
  return crc;
}

inline void append(std::vector<std::uint8_t>& stream, const std::vector<std::uint8_t>& bytes) {
  stream.insert(stream.end(), bytes.begin(), bytes.end());
}

}  // namespace harness
}  // namespace imubridge::protocol
