#include "protocol/xbee.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstddef>
#include <nlohmann/json.hpp>
#include <ostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "tests/support/decoder_harness.hpp"

namespace imubridge::protocol {

// Readable failure messages for the EXPECT_EQs below.
namespace xbee {
void PrintTo(const Frame& f, std::ostream* os) { *os << nlohmann::json(f).dump(); }
}  // namespace xbee

namespace {

using namespace xbee;
using Bytes = std::vector<std::uint8_t>;
using harness::append;

// "7E 00 04" -> {0x7E, 0x00, 0x04}
Bytes from_hex(std::string_view text) {
  std::istringstream in{std::string(text)};
  Bytes out;
  for (unsigned byte = 0; in >> std::hex >> byte;) out.push_back(static_cast<std::uint8_t>(byte));
  return out;
}

Bytes bytes_of(std::string_view s) { return {s.begin(), s.end()}; }

Bytes wire(const Frame& frame, ApiMode mode) {
  Bytes out;
  encode(frame, mode, out);
  return out;
}

Frame rx(std::uint64_t source64, Bytes payload) {
  return {kRxPacket,
          RxPacket{.source64 = source64, .source16 = 0xFFFE, .options = 0x01, .payload = std::move(payload)}};
}

using Decoded = harness::Decoded<Decoder>;

// Feeds `stream` in chunks of `chunk` bytes (0: all at once), then finishes.
Decoded decode(ApiMode mode, const Bytes& stream, std::size_t chunk = 0) {
  return harness::decode_chunked(Decoder(mode), stream, chunk);
}

// Every byte is in an emitted frame or discarded; the encoding is canonical, so a frame's wire size is its encoding's.
void expect_accounted(ApiMode mode, const Decoded& d) {
  std::uint64_t frame_bytes = 0;
  for (const Frame& f : d.frames) frame_bytes += wire(f, mode).size();
  EXPECT_EQ(d.counters.bytes_in, frame_bytes + d.counters.bytes_discarded);
}

TEST(XbeeChecksum, PublishedAtCommandExample) {
  EXPECT_EQ(checksum(from_hex("08 01 4E 4A")), 0x5E);
  // Digi's "AT NJ" example frame.
  EXPECT_EQ(wire({0x08, OtherFrame{from_hex("01 4E 4A")}}, ApiMode::unescaped), from_hex("7E 00 04 08 01 4E 4A 5E"));
}

TEST(XbeeEncode, PublishedEscapeExample) {
  // Digi's API-mode-2 example: 0x11 (XON) is escaped, length and checksum are over the unescaped data.
  const Frame frame{0x23, OtherFrame{{0x11}}};
  EXPECT_EQ(wire(frame, ApiMode::escaped), from_hex("7E 00 02 23 7D 31 CB"));
  EXPECT_EQ(wire(frame, ApiMode::unescaped), from_hex("7E 00 02 23 11 CB"));
}

// Digi's receive-packet example: 0013A20040522BAA (16-bit 7D84) sends "RxData", acknowledged.
const Frame kDigiRx{kRxPacket, RxPacket{0x0013A20040522BAA, 0x7D84, 0x01, bytes_of("RxData")}};
constexpr std::string_view kDigiRxWire = "7E 00 12 90 00 13 A2 00 40 52 2B AA 7D 84 01 52 78 44 61 74 61 0D";

TEST(XbeeDecode, PublishedRxPacket) {
  const Decoded d = decode(ApiMode::unescaped, from_hex(kDigiRxWire));
  EXPECT_EQ(d.frames, std::vector{kDigiRx});
  EXPECT_EQ(wire(kDigiRx, ApiMode::unescaped), from_hex(kDigiRxWire));
}

TEST(XbeeDecode, PublishedRxPacketEscaped) {
  // Same frame in mode 2: the 0x13 of the 64-bit address and the 0x7D of the 16-bit one are escaped.
  const Bytes escaped = from_hex("7E 00 12 90 00 7D 33 A2 00 40 52 2B AA 7D 5D 84 01 52 78 44 61 74 61 0D");
  EXPECT_EQ(wire(kDigiRx, ApiMode::escaped), escaped);
  EXPECT_EQ(decode(ApiMode::escaped, escaped).frames, std::vector{kDigiRx});
}

TEST(XbeeDecode, PublishedTxRequest) {
  // Digi's broadcast "Hello XBee!" transmit request.
  const Bytes bytes =
      from_hex("7E 00 19 10 01 00 00 00 00 00 00 FF FF FF FE 00 00 48 65 6C 6C 6F 20 58 42 65 65 21 5A");
  const Frame expected{kTxRequest, TxRequest{0x01, 0xFFFF, 0xFFFE, 0x00, 0x00, bytes_of("Hello XBee!")}};
  EXPECT_EQ(decode(ApiMode::unescaped, bytes).frames, std::vector{expected});
  EXPECT_EQ(wire(expected, ApiMode::unescaped), bytes);
}

TEST(XbeeDecode, PublishedTxStatus) {
  // Digi's transmit-status example: frame 1 to 7D84 delivered with no retries after an address discovery.
  const Bytes bytes = from_hex("7E 00 07 8B 01 7D 84 00 00 01 71");
  const Frame expected{kTxStatus, TxStatus{0x01, 0x7D84, 0, 0x00, 0x01}};
  EXPECT_EQ(decode(ApiMode::unescaped, bytes).frames, std::vector{expected});
}

TEST(XbeeDecode, OtherTypesComeOutGenericAndCounted) {
  // Digi's modem-status example ("coordinator started"), a type with no typed body.
  const Decoded d = decode(ApiMode::unescaped, from_hex("7E 00 02 8A 06 6F"));
  EXPECT_EQ(d.frames, (std::vector<Frame>{{0x8A, OtherFrame{{0x06}}}}));
  EXPECT_EQ(d.counters, (DecoderCounters{.bytes_in = 6, .frames_out = 1, .unsupported = 1}));
}

TEST(XbeeDecode, KnownTypesTooShortForTheirFieldsComeOutGeneric) {
  // An RX packet one byte short of its address and options fields, and a TX status with an extra byte.
  const Frame short_rx{kRxPacket, OtherFrame{Bytes(10, 0xAB)}};
  const Frame long_status{kTxStatus, OtherFrame{Bytes(7, 0x01)}};
  Bytes stream = wire(short_rx, ApiMode::unescaped);
  append(stream, wire(long_status, ApiMode::unescaped));
  const Decoded d = decode(ApiMode::unescaped, stream);
  EXPECT_EQ(d.frames, (std::vector{short_rx, long_status}));
  EXPECT_EQ(d.counters.unsupported, 2u);
}

TEST(XbeeEncode, RejectsBodyOfAnotherType) {
  Bytes out;
  EXPECT_THROW(encode({kTxRequest, RxPacket{}}, ApiMode::unescaped, out), std::invalid_argument);
  EXPECT_THROW(encode({kRxPacket, TxStatus{}}, ApiMode::escaped, out), std::invalid_argument);
}

class XbeeModes : public testing::TestWithParam<ApiMode> {};
INSTANTIATE_TEST_SUITE_P(BothModes, XbeeModes, testing::Values(ApiMode::unescaped, ApiMode::escaped),
                         [](const auto& info) { return info.param == ApiMode::escaped ? "escaped" : "unescaped"; });

// Frames whose every field is full of the bytes mode 2 must escape, plus every byte value in a payload.
std::vector<Frame> awkward_frames() {
  Bytes every_value(256);
  for (std::size_t i = 0; i < every_value.size(); ++i) every_value[i] = static_cast<std::uint8_t>(i);
  const Bytes reserved = from_hex("7E 7D 11 13 7E 7E 7D 7D 13 11");
  return {
      {kRxPacket, RxPacket{0x7E7D11137E7D1113, 0x7D7E, 0x11, reserved}},
      {kRxPacket, RxPacket{0x0013A20040A1B2C3, 0xFFFE, 0x02, every_value}},
      {kRxPacket, RxPacket{0x0013A20040A1B2C3, 0x0000, 0x00, {}}},
      {kTxRequest, TxRequest{0x7E, 0x000000000000FFFF, 0xFFFE, 0x13, 0x7D, reserved}},
      {kTxStatus, TxStatus{0x7D, 0x7E11, 0x13, 0x7E, 0x7D}},
      {0x8A, OtherFrame{reserved}},
  };
}

TEST_P(XbeeModes, RoundTripsAwkwardFrames) {
  const std::vector<Frame> frames = awkward_frames();
  Bytes stream;
  for (const Frame& f : frames) encode(f, GetParam(), stream);
  const Decoded d = decode(GetParam(), stream);
  EXPECT_EQ(d.frames, frames);
  EXPECT_EQ(d.counters, (DecoderCounters{.bytes_in = stream.size(), .frames_out = frames.size(), .unsupported = 1}));
}

TEST(XbeeEncode, EscapedWireHasNoRawReservedByteAfterTheDelimiter) {
  for (const Frame& f : awkward_frames()) {
    const Bytes w = wire(f, ApiMode::escaped);
    EXPECT_EQ(w[0], kStartDelimiter);
    for (std::size_t i = 1; i < w.size(); ++i) {
      EXPECT_NE(w[i], 0x7E);
      EXPECT_NE(w[i], 0x11);
      EXPECT_NE(w[i], 0x13);
      if (w[i] == 0x7D) {
        ASSERT_LT(i + 1, w.size());
        const std::uint8_t unescaped = w[++i] ^ 0x20;
        EXPECT_TRUE(unescaped == 0x7E || unescaped == 0x7D || unescaped == 0x11 || unescaped == 0x13);
      }
    }
  }
}

TEST_P(XbeeModes, LengthBound) {
  // Frame data of exactly kMaxFrameData bytes passes; one more cannot be encoded.
  const Frame largest = rx(1, Bytes(kMaxFrameData - 12, 0x7E));
  EXPECT_EQ(decode(GetParam(), wire(largest, GetParam())).frames, std::vector{largest});
  Bytes out;
  EXPECT_THROW(encode(rx(1, Bytes(kMaxFrameData - 11, 0)), GetParam(), out), std::invalid_argument);

  // Declared lengths of 0 and kMaxFrameData + 1 are false starts that give up their delimiter; the frame after each
  // is found.
  const Frame good = rx(2, bytes_of("ok"));
  Bytes stream = from_hex("7E 00 00");
  append(stream, wire(good, GetParam()));
  append(stream, from_hex("7E 04 01"));
  append(stream, wire(good, GetParam()));
  const Decoded d = decode(GetParam(), stream);
  EXPECT_EQ(d.frames, (std::vector{good, good}));
  EXPECT_EQ(d.counters,
            (DecoderCounters{.bytes_in = stream.size(), .frames_out = 2, .resyncs = 2, .bytes_discarded = 6}));
}

// `w` with the first occurrence of `from` replaced by `to`.
Bytes replaced(Bytes w, const Bytes& from, const Bytes& to) {
  const auto at = std::search(w.begin(), w.end(), from.begin(), from.end());
  EXPECT_NE(at, w.end());
  w.insert(w.erase(at, at + static_cast<std::ptrdiff_t>(from.size())), to.begin(), to.end());
  return w;
}

Bytes prefix(const Bytes& w, std::size_t n) { return {w.begin(), w.begin() + static_cast<std::ptrdiff_t>(n)}; }

// A rejected piece with no other 0x7E is discarded whole: its delimiter, then every byte up to the next delimiter.
void expect_discarded_whole(const Bytes& piece) { EXPECT_EQ(std::count(piece.begin() + 1, piece.end(), 0x7E), 0); }

// A stream mixing valid frames with garbage and false starts of every kind the mode has.
Bytes messy_stream(ApiMode mode) {
  Bytes stream = from_hex("00 7D 11 7E 00 00 13");
  for (const Frame& f : awkward_frames()) {
    append(stream, wire(f, mode));
    Bytes broken = wire(f, mode);
    broken[broken.size() / 2] ^= 0x04;
    append(stream, broken);
    append(stream, prefix(broken, 5));
  }
  // Lets the last cut frame's declared length run out inside the stream, then leaves one unfinished at the end.
  append(stream, Bytes(kMaxFrameData, 0x00));
  append(stream, from_hex("7E 00 05 90"));
  return stream;
}

TEST_P(XbeeModes, AnySplitGivesTheSameFramesAndCounters) {
  const Bytes stream = messy_stream(GetParam());
  const Decoded whole = decode(GetParam(), stream);
  // Every intact frame is found: no false start can hide one.
  EXPECT_EQ(whole.frames, awkward_frames());
  expect_accounted(GetParam(), whole);

  const Decoded bytewise = decode(GetParam(), stream, 1);
  EXPECT_EQ(bytewise.frames, whole.frames);
  EXPECT_EQ(bytewise.counters, whole.counters);
  EXPECT_EQ(harness::first_split_that_differs(Decoder(GetParam()), stream, whole), std::nullopt);
}

TEST(XbeeDecode, UnescapedGarbageTruncationBitFlipsAndBadLength) {
  constexpr ApiMode kMode = ApiMode::unescaped;
  const Frame a = rx(0xA, bytes_of("first")), c = rx(0xC, bytes_of("third")), e = rx(0xE, bytes_of("fifth frame"));
  const Frame f = rx(0xF, bytes_of("sixth frame")), g = rx(0x6, bytes_of("last"));
  const Bytes flipped = replaced(wire(rx(0xB, bytes_of("second")), kMode), bytes_of("second"), bytes_of("secoNd"));
  // The cut frame's declared length swallows most of e: the swallowed bytes fail its checksum and are searched again.
  const Bytes cut = prefix(wire(rx(0xD, bytes_of("fourth, cut")), kMode), 6);
  expect_discarded_whole(flipped);
  expect_discarded_whole(cut);

  Bytes stream = from_hex("01 02 03");
  for (const Bytes& piece : {wire(a, kMode), flipped, wire(c, kMode), cut, wire(e, kMode), wire(f, kMode),
                             from_hex("7E 00 00"), wire(g, kMode), from_hex("7E 00 05 90")}) {
    append(stream, piece);
  }
  const Decoded d = decode(kMode, stream);
  EXPECT_EQ(d.frames, (std::vector{a, c, e, f, g}));
  // Discarded: the garbage, the flipped and the cut frame, the zero-length header, and the tail left at finish(),
  // which is a false start too: cut off by the end of the stream.
  EXPECT_EQ(d.counters, (DecoderCounters{.bytes_in = stream.size(),
                                         .frames_out = 5,
                                         .crc_failures = 2,
                                         .resyncs = 4,
                                         .bytes_discarded = 3 + flipped.size() + cut.size() + 3 + 4}));
}

TEST(XbeeDecode, EscapedGarbageCutFramesBadEscapesAndBitFlips) {
  constexpr ApiMode kMode = ApiMode::escaped;
  const Frame a = rx(0xA, from_hex("11 7E 7D 13")), d = rx(0xD, bytes_of("after the cut")),
              g = rx(0x6, bytes_of("end"));
  // 0x7D 0x21 unescapes to 0x01, which is never escaped.
  const Bytes bad_escape = replaced(wire(rx(0xB, from_hex("11 22")), kMode), from_hex("7D 31"), from_hex("7D 21"));
  // The next frame's delimiter arrives before this one is complete.
  const Bytes cut = prefix(wire(rx(0xC, bytes_of("cut short")), kMode), 9);
  const Bytes raw_xon = replaced(wire(rx(0xE, from_hex("11 22")), kMode), from_hex("7D 31"), from_hex("11"));
  const Bytes flipped = replaced(wire(rx(0xF, bytes_of("plain")), kMode), bytes_of("plain"), bytes_of("plaim"));
  for (const Bytes& piece : {bad_escape, cut, raw_xon, flipped}) expect_discarded_whole(piece);

  Bytes stream = from_hex("7D 5E 11");
  for (const Bytes& piece :
       {wire(a, kMode), bad_escape, cut, wire(d, kMode), raw_xon, flipped, wire(g, kMode), from_hex("7E 00")}) {
    append(stream, piece);
  }
  const Decoded decoded = decode(kMode, stream);
  EXPECT_EQ(decoded.frames, (std::vector{a, d, g}));
  EXPECT_EQ(decoded.counters, (DecoderCounters{.bytes_in = stream.size(),
                                               .frames_out = 3,
                                               .crc_failures = 1,
                                               .resyncs = 5,  // the last: "7E 00", cut off by the end
                                               .bytes_discarded = 3 + bad_escape.size() + cut.size() + raw_xon.size() +
                                                                  flipped.size() + 2}));
}

TEST(XbeeDecode, FrameInsideRejectedOneIsFound) {
  constexpr ApiMode kMode = ApiMode::unescaped;
  const Frame inner = rx(0x1, bytes_of("inner"));
  // An RX packet carrying a whole frame as payload, with its own checksum broken: the inner frame still comes out.
  Bytes outer = wire(rx(0x2, wire(inner, kMode)), kMode);
  outer.back() ^= 0xFF;
  // A bare header declaring 32 bytes: it swallows the next frame whole before its checksum fails.
  Bytes stream = from_hex("7E 00 20");
  append(stream, wire(inner, kMode));
  append(stream, outer);

  const Decoded d = decode(kMode, stream);
  EXPECT_EQ(d.frames, (std::vector{inner, inner}));
  const std::size_t inner_size = wire(inner, kMode).size();
  EXPECT_EQ(d.counters, (DecoderCounters{.bytes_in = stream.size(),
                                         .frames_out = 2,
                                         .crc_failures = 2,
                                         .resyncs = 2,
                                         .bytes_discarded = 3 + (outer.size() - inner_size)}));
}

TEST(XbeeDecode, FinishDiscardsTheUnfinishedFrameAndStartsAfresh) {
  const Bytes frame = wire(kDigiRx, ApiMode::unescaped);
  Decoder decoder(ApiMode::unescaped);
  std::vector<Frame> frames;
  decoder.feed(prefix(frame, 10), frames);
  decoder.finish(frames);
  decoder.feed(frame, frames);
  decoder.finish(frames);
  EXPECT_EQ(frames, std::vector{kDigiRx});
  // The cut-off candidate is a false start; its other 9 bytes hold no delimiter.
  EXPECT_EQ(decoder.counters(),
            (DecoderCounters{.bytes_in = 10 + frame.size(), .frames_out = 1, .resyncs = 1, .bytes_discarded = 10}));
}

TEST_P(XbeeModes, FinishFindsAFrameInsideACutOffFalseStart) {
  // Near the end of the stream a corrupted header declares 64 bytes, more than remain. In mode 1 only the end of the
  // stream refutes it, and the frame inside comes out of finish(); in mode 2 that frame's delimiter already did.
  const Frame a = rx(0xA, bytes_of("first")), g = rx(0x6, bytes_of("last"));
  const Bytes false_start = from_hex("7E 00 40");
  Bytes stream = wire(a, GetParam());
  append(stream, false_start);
  append(stream, wire(g, GetParam()));
  ASSERT_LT(wire(g, GetParam()).size(), 64u);

  Decoder decoder(GetParam());
  std::vector<Frame> frames;
  decoder.feed(stream, frames);
  EXPECT_EQ(frames, (GetParam() == ApiMode::escaped ? std::vector{a, g} : std::vector{a}));
  decoder.finish(frames);
  const Decoded whole{frames, decoder.counters()};
  EXPECT_EQ(whole.frames, (std::vector{a, g}));
  EXPECT_EQ(whole.counters,
            (DecoderCounters{
                .bytes_in = stream.size(), .frames_out = 2, .resyncs = 1, .bytes_discarded = false_start.size()}));
  EXPECT_EQ(harness::first_split_that_differs(Decoder(GetParam()), stream, whole), std::nullopt);
}

TEST(XbeeJson, RxPacketFieldsAsHex) {
  const nlohmann::json j = kDigiRx;
  EXPECT_EQ(j, (nlohmann::json{{"protocol", "xbee"},
                               {"frame_type", 0x90},
                               {"frame_type_name", "rx_packet"},
                               {"source64", "0013A20040522BAA"},
                               {"source16", "7D84"},
                               {"options", 1},
                               {"payload", "527844617461"}}));
}

TEST(XbeeJson, TxStatusAndOtherFrames) {
  const nlohmann::json status = Frame{kTxStatus, TxStatus{0x01, 0x7D84, 2, 0x21, 0x01}};
  EXPECT_EQ(status, (nlohmann::json{{"protocol", "xbee"},
                                    {"frame_type", 0x8B},
                                    {"frame_type_name", "tx_status"},
                                    {"frame_id", 1},
                                    {"destination16", "7D84"},
                                    {"retries", 2},
                                    {"delivery_status", 0x21},
                                    {"discovery_status", 1}}));
  const nlohmann::json other = Frame{0x8A, OtherFrame{{0x06}}};
  EXPECT_EQ(other,
            (nlohmann::json{{"protocol", "xbee"}, {"frame_type", 0x8A}, {"frame_type_name", "other"}, {"data", "06"}}));
}

}  // namespace
}  // namespace imubridge::protocol
