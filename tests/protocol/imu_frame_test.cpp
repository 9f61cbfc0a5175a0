#include "protocol/imu_frame.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <random>
#include <vector>

#include "protocol/crc.hpp"
#include "tests/support/decoder_harness.hpp"

namespace imubridge::protocol::imu {
void PrintTo(const Frame& f, std::ostream* os) { *os << nlohmann::json(f).dump(); }

namespace {

using Bytes = std::vector<std::uint8_t>;
using harness::append;
using harness::crc_bit_serial;

// The IMU sample frame of docs/protocol.md, written byte by byte from the layout table.
const Bytes kDocVector = {
    0xB7, 0x4D,                                      // sync
    0x01,                                            // version 1
    0x01,                                            // type: IMU sample
    0x14,                                            // payload length 20
    0x39, 0x30,                                      // seq 12345
    0x9A, 0x78, 0x56, 0x34, 0x12, 0x00, 0x00, 0x00,  // device time 0x123456789A us
    0x02, 0x08, 0xFB, 0x07, 0xF7, 0x05,              // accel 2050, 2043, 1527
    0xF4, 0xFF, 0x05, 0x00, 0x2C, 0x01,              // gyro -12, 5, 300
    0xD2, 0x00, 0xA1, 0xFF, 0x20, 0xFE,              // mag 210, -95, -480
    0x80, 0xC1,                                      // temperature -16000
    0x39, 0xB8,                                      // CRC 0xB839
};

Frame imu_sample(std::uint16_t seq) {
  const auto s = static_cast<std::int16_t>(seq);
  return {seq, seq, 1'000'000u + 10'000u * seq, ImuRaw{{2048, 2050, 1527}, {-3, 4, s}, {210, -95, -480}, -16000}};
}

Frame velocity_estimate(std::uint16_t seq) {
  return {seq, seq, 2'000'000u + 20'000u * seq, VelocityEstimate{0.25f * seq, -1.5f, 0.125f, 0.0625f}};
}

Bytes encoded(const Frame& frame) {
  Bytes out;
  encode(frame, out);
  return out;
}

// A well-formed frame of a type this decoder does not know.
Bytes unknown_type_frame(std::uint16_t seq) {
  Bytes f = {kSync0, kSync1, kVersion, 0x7E, 4, static_cast<std::uint8_t>(seq), static_cast<std::uint8_t>(seq >> 8)};
  f.resize(kHeaderSize, 0);  // device time 0
  append(f, {1, 2, 3, 4});
  const std::uint16_t crc = crc_bit_serial(std::span(f).subspan(2));
  append(f, {static_cast<std::uint8_t>(crc), static_cast<std::uint8_t>(crc >> 8)});
  return f;
}

// Sync bytes after the first two would let a corrupted frame produce extra false starts; tests that count false
// starts exactly use frames without them.
bool sync_bytes_only_in_front(const Bytes& frame) {
  return std::none_of(frame.begin() + 2, frame.end(), [](std::uint8_t b) { return b == kSync0 || b == kSync1; });
}

using Decoded = harness::Decoded<Decoder>;

// Feeds `stream` in pieces of `chunk` bytes (0: all at once), then finishes.
Decoded decode(std::span<const std::uint8_t> stream, std::size_t chunk = 0) {
  return harness::decode_chunked(Decoder{}, stream, chunk);
}

std::uint64_t bytes_in_frames(const std::vector<Frame>& frames) {
  std::uint64_t n = 0;
  for (const Frame& f : frames) n += encoded_size(f);
  return n;
}

TEST(ImuFrame, DocumentedTestVector) {
  ASSERT_EQ(kDocVector.size(), kHeaderSize + kImuSamplePayloadSize + kCrcSize);
  EXPECT_EQ(crc_bit_serial(std::span(kDocVector).subspan(2, 33)), 0xB839);

  const Frame frame{12345, 12345, 0x123456789A, ImuRaw{{2050, 2043, 1527}, {-12, 5, 300}, {210, -95, -480}, -16000}};
  EXPECT_EQ(encoded(frame), kDocVector);

  const Decoded d = decode(kDocVector);
  ASSERT_EQ(d.frames.size(), 1u);
  EXPECT_EQ(d.frames[0], frame);
  EXPECT_EQ(d.frames[0].type(), MsgType::imu_sample);
}

TEST(ImuFrame, ImuSampleRoundTrip) {
  constexpr std::int16_t lo = std::numeric_limits<std::int16_t>::min(), hi = std::numeric_limits<std::int16_t>::max();
  const Frame frame{65535, 65535, std::numeric_limits<std::uint64_t>::max(),
                    ImuRaw{{lo, hi, 0}, {-1, 1, lo}, {hi, -2, 2}, lo}};
  const Decoded d = decode(encoded(frame));
  ASSERT_EQ(d.frames.size(), 1u);
  EXPECT_EQ(d.frames[0], frame);
}

TEST(ImuFrame, VelocityEstimateRoundTrip) {
  const Frame frame{7, 7, 123456789, VelocityEstimate{-3.75f, 1e-7f, std::numeric_limits<float>::max(), 0.0f}};
  const Bytes bytes = encoded(frame);
  EXPECT_EQ(bytes.size(), kHeaderSize + kVelocityEstimatePayloadSize + kCrcSize);
  EXPECT_EQ(bytes[3], 0x02);
  const Decoded d = decode(bytes);
  ASSERT_EQ(d.frames.size(), 1u);
  EXPECT_EQ(d.frames[0], frame);
  EXPECT_EQ(d.frames[0].type(), MsgType::velocity_estimate);
}

TEST(ImuFrame, EncodeAppends) {
  Bytes out = {0xAA};
  encode(imu_sample(1), out);
  encode(velocity_estimate(2), out);
  const Bytes first = encoded(imu_sample(1)), second = encoded(velocity_estimate(2));
  ASSERT_EQ(out.size(), 1 + first.size() + second.size());
  EXPECT_TRUE(std::equal(first.begin(), first.end(), out.begin() + 1));
  EXPECT_TRUE(std::equal(second.begin(), second.end(), out.begin() + 1 + static_cast<std::ptrdiff_t>(first.size())));
}

TEST(ImuFrame, Json) {
  const nlohmann::json imu = Frame{3, 65539, 42, ImuRaw{{1, 2, 3}, {4, 5, 6}, {7, 8, 9}, -10}};
  EXPECT_EQ(imu, nlohmann::json::parse(R"({"protocol":"imubridge","seq":3,"sequence":65539,"type":"imu_sample",
      "device_time_us":42,"accel":[1,2,3],"gyro":[4,5,6],"mag":[7,8,9],"temperature":-10})"));
  const nlohmann::json velocity = velocity_estimate(4);
  EXPECT_EQ(velocity["type"], "velocity_estimate");
  EXPECT_EQ(velocity["vx"], 1.0);
  EXPECT_EQ(velocity["sigma_vy"], 0.0625);
}

// A stream with every kind of trouble: noise with stray sync bytes, a corrupted frame, a false start that hides a
// real frame, a long unknown-type candidate, an unsupported frame, and a truncated tail.
Bytes troubled_stream() {
  Bytes s = {0x00, kSync0, 0x12, kSync1, 0xFF};
  append(s, encoded(imu_sample(1)));
  Bytes corrupted = encoded(imu_sample(2));
  corrupted[20] ^= 0x10;
  append(s, corrupted);
  append(s, {kSync0, kSync1, kVersion, 0x01, 0x14});  // claims an IMU sample; a real one starts inside it
  append(s, encoded(velocity_estimate(3)));
  append(s, {kSync0, kSync1, kVersion, 0x7F, 0xFF});  // claims 255 bytes of an unknown type
  for (std::uint16_t seq = 4; seq < 12; ++seq) append(s, encoded(imu_sample(seq)));
  append(s, unknown_type_frame(12));
  append(s, {kSync0, kSync1, 0x02});  // bad version
  append(s, encoded(velocity_estimate(13)));
  const Bytes last = encoded(imu_sample(14));
  s.insert(s.end(), last.begin(), last.begin() + 30);
  return s;
}

TEST(ImuFrameDecoder, SameFramesAndCountersAtEverySplitPoint) {
  const Bytes stream = troubled_stream();
  const Decoded whole = decode(stream);
  ASSERT_EQ(whole.frames.size(), 11u);    // seq 1, 3..11, 13: the stream exercises what it claims to
  ASSERT_EQ(whole.counters.resyncs, 5u);  // the last of them: the frame cut off by the end of the stream

  EXPECT_EQ(harness::first_split_that_differs(Decoder{}, stream, whole), std::nullopt);
}

TEST(ImuFrameDecoder, SameFramesAndCountersForAnyChunkSize) {
  Bytes stream;
  for (int i = 0; i < 20; ++i) append(stream, troubled_stream());
  const Decoded whole = decode(stream);
  for (std::size_t chunk : {1u, 2u, 3u, 36u, 37u, 38u, 271u, 272u, 273u, 4096u, 65536u}) {
    const Decoded d = decode(stream, chunk);
    EXPECT_EQ(d.frames, whole.frames) << "chunk " << chunk;
    EXPECT_EQ(d.counters, whole.counters) << "chunk " << chunk;
  }
}

TEST(ImuFrameDecoder, GarbageTruncationAndCorruption) {
  const Bytes noise = {0x00, 0x11, 0xFF, kSync1, 0x42, 0x07, 0xB6};  // no first sync byte anywhere
  const Bytes f0 = encoded(imu_sample(0)), f2 = encoded(imu_sample(2)), f4 = encoded(imu_sample(4));
  Bytes f1 = encoded(imu_sample(1)), f3 = encoded(velocity_estimate(3));
  for (const Bytes& f : {f0, f1, f2, f3, f4}) ASSERT_TRUE(sync_bytes_only_in_front(f));
  f1[kHeaderSize + 3] ^= 0x01;  // one payload bit
  f3.resize(20);                // cut short: the next frame's bytes complete its claimed length

  Bytes stream = f0;
  for (const Bytes& part : {noise, f1, f2, f3, f4}) append(stream, part);
  const Decoded d = decode(stream);

  EXPECT_EQ(d.frames, (std::vector<Frame>{imu_sample(0), imu_sample(2), imu_sample(4)}));
  EXPECT_EQ(d.counters, (DecoderCounters{.bytes_in = stream.size(),
                                         .frames_out = 3,
                                         .crc_failures = 2,  // f1, and f3 completed by f4's bytes
                                         .resyncs = 2,
                                         .bytes_discarded = noise.size() + f1.size() + f3.size(),
                                         .sequence_gaps = 2,  // 0 -> 2 and 2 -> 4
                                         .frames_lost = 2}));
}

TEST(ImuFrameDecoder, EverySingleBitFlipIsRejectedAndCounted) {
  const Bytes before = encoded(imu_sample(0)), clean = encoded(imu_sample(1)), after = encoded(imu_sample(2));
  for (const Bytes& f : {before, clean, after}) ASSERT_TRUE(sync_bytes_only_in_front(f));

  for (std::size_t bit = 0; bit < 8 * clean.size(); ++bit) {
    Bytes flipped = clean;
    flipped[bit / 8] ^= static_cast<std::uint8_t>(1u << (bit % 8));
    Bytes stream = before;
    append(stream, flipped);
    append(stream, after);
    const Decoded d = decode(stream);

    // A broken sync is plain noise; a broken version or IMU length is caught by the header; the type byte of an
    // IMU sample never flips into another known type, so that and everything else is left to the CRC.
    const std::size_t byte = bit / 8;
    const bool header_caught = byte == 2 || byte == 4;
    const bool crc_caught = byte >= 3 && !header_caught;
    EXPECT_EQ(d.frames, (std::vector<Frame>{imu_sample(0), imu_sample(2)})) << "bit " << bit;
    EXPECT_EQ(d.counters, (DecoderCounters{.bytes_in = stream.size(),
                                           .frames_out = 2,
                                           .crc_failures = crc_caught ? 1u : 0u,
                                           .resyncs = header_caught || crc_caught ? 1u : 0u,
                                           .bytes_discarded = clean.size(),
                                           .sequence_gaps = 1,
                                           .frames_lost = 1}))
        << "bit " << bit;
  }
}

TEST(ImuFrameDecoder, FindsFrameStartingInsideRejectedCandidate) {
  struct Case {
    const char* name;
    Bytes false_start;
    std::uint64_t crc_failures;
  };
  const std::vector<Case> cases = {
      {"bad CRC", {kSync0, kSync1, kVersion, 0x01, 0x14}, 1},
      {"bad version", {kSync0, kSync1, 0x02, 0x01, 0x14}, 0},
      {"bad length", {kSync0, kSync1, kVersion, 0x02, 0x14}, 0},
      {"long unknown type, bad CRC", {kSync0, kSync1, kVersion, 0x7F, 0xFF}, 1},
  };
  for (const Case& c : cases) {
    Bytes stream = c.false_start;
    std::vector<Frame> expected;
    for (std::uint16_t seq = 0; seq < 8; ++seq) {  // 8 frames outlast even a 255-byte claimed payload
      append(stream, encoded(imu_sample(seq)));
      expected.push_back(imu_sample(seq));
    }
    const Decoded d = decode(stream, 1);
    EXPECT_EQ(d.frames, expected) << c.name;
    EXPECT_EQ(d.counters, (DecoderCounters{.bytes_in = stream.size(),
                                           .frames_out = 8,
                                           .crc_failures = c.crc_failures,
                                           .resyncs = 1,
                                           .bytes_discarded = c.false_start.size()}))
        << c.name;
  }
}

TEST(ImuFrameDecoder, UnsupportedTypeIsCountedAndSkippedWhole) {
  const Bytes unknown = unknown_type_frame(1);
  Bytes stream = encoded(imu_sample(0));
  append(stream, unknown);
  append(stream, encoded(imu_sample(2)));
  const Decoded d = decode(stream);
  EXPECT_EQ(d.frames, (std::vector<Frame>{imu_sample(0), imu_sample(2)}));
  EXPECT_EQ(d.counters, (DecoderCounters{.bytes_in = stream.size(),
                                         .frames_out = 2,
                                         .bytes_discarded = unknown.size(),
                                         .unsupported = 1}));  // and no gap: it used up seq 1
}

TEST(ImuFrameDecoder, SequenceWrapsAndGaps) {
  Bytes stream;
  for (std::uint16_t seq : {65534, 65535, 0, 1, 5}) append(stream, encoded(imu_sample(seq)));
  const Decoded d = decode(stream);
  std::vector<std::uint64_t> sequences;
  for (const Frame& f : d.frames) sequences.push_back(f.sequence);
  // The first frame starts the count at its own number.
  EXPECT_EQ(sequences, (std::vector<std::uint64_t>{65534, 65535, 65536, 65537, 65541}));
  EXPECT_EQ(d.counters.sequence_gaps, 1u);
  EXPECT_EQ(d.counters.frames_lost, 3u);
}

TEST(ImuFrameDecoder, ARestartedSenderContinuesTheCountWithoutInventingALoss) {
  // Numbered and timed from zero again after frame 5000: the unwrapped count goes on, the clock starts a new epoch.
  Bytes stream;
  for (std::uint16_t seq : {4998, 4999, 5000, 0, 1, 2, 4}) {
    Frame f = imu_sample(seq);
    f.device_time_us = seq * 1000u;
    append(stream, encoded(f));
  }
  const Decoded d = decode(stream);
  std::vector<std::uint64_t> sequences;
  std::vector<std::uint32_t> epochs;
  for (const Frame& f : d.frames) sequences.push_back(f.sequence), epochs.push_back(f.clock_epoch);
  EXPECT_EQ(sequences, (std::vector<std::uint64_t>{4998, 4999, 5000, 5001, 5002, 5003, 5005}));
  EXPECT_EQ(epochs, (std::vector<std::uint32_t>{0, 0, 0, 1, 1, 1, 1}));
  EXPECT_EQ(d.counters.device_restarts, 1u);
  EXPECT_EQ(d.counters.frames_lost, 1u) << "frame 3 of the new count only";
  EXPECT_EQ(d.counters.sequence_gaps, 1u);
}

TEST(ImuFrameDecoder, RepeatedSequenceNumberIsADuplicateNotALoss) {
  // A radio that retransmits delivers the same frame twice; a repeated number is dropped whatever the frame holds.
  const Bytes first = encoded(imu_sample(7)), next = encoded(velocity_estimate(8));
  Frame changed = velocity_estimate(8);
  std::get<VelocityEstimate>(changed.payload).vx = 99;
  Bytes stream;
  for (const Bytes& f : {first, first, first, next, encoded(changed)}) append(stream, f);
  append(stream, encoded(imu_sample(10)));

  const Decoded d = decode(stream);
  EXPECT_EQ(d.frames, (std::vector<Frame>{imu_sample(7), velocity_estimate(8), imu_sample(10)}));
  EXPECT_EQ(d.counters, (DecoderCounters{.bytes_in = stream.size(),
                                         .frames_out = 3,
                                         .bytes_discarded = 2 * first.size() + next.size(),
                                         .sequence_gaps = 1,  // 8 -> 10: the repeats do not hide it
                                         .frames_lost = 1,
                                         .duplicates = 3}));
}

TEST(ImuFrameDecoder, FinishDiscardsTheTruncatedTail) {
  const Bytes next = encoded(imu_sample(1));
  ASSERT_TRUE(sync_bytes_only_in_front(next));
  for (std::size_t tail : {std::size_t{1}, std::size_t{30}}) {  // a lone sync byte; a frame cut short
    Bytes stream = encoded(imu_sample(0));
    stream.insert(stream.end(), next.begin(), next.begin() + static_cast<std::ptrdiff_t>(tail));

    Decoder decoder;
    std::vector<Frame> frames;
    decoder.feed(stream, frames);
    EXPECT_EQ(frames, std::vector<Frame>{imu_sample(0)});
    EXPECT_EQ(decoder.counters().bytes_discarded, 0u);  // the tail may still become a frame

    decoder.finish(frames);
    EXPECT_EQ(frames, std::vector<Frame>{imu_sample(0)});
    EXPECT_EQ(decoder.counters().bytes_discarded, tail);
    EXPECT_EQ(decoder.counters().resyncs, 1u);  // a candidate cut off by the end is a false start
    EXPECT_EQ(decoder.counters().bytes_in, bytes_in_frames(frames) + decoder.counters().bytes_discarded);
    decoder.finish(frames);
    EXPECT_EQ(decoder.counters().bytes_discarded, tail) << "a second finish() must not count the tail again";
  }
}

TEST(ImuFrameDecoder, FinishFindsFramesInsideACutOffFalseStart) {
  // Near the end of the stream, a corrupted header claims a 255-byte payload of an unknown type: more bytes than
  // remain, so only the end of the stream refutes it, and the two frames inside it come out of finish().
  const Bytes false_start = {kSync0, kSync1, kVersion, 0x7F, 0xFF};
  Bytes stream = encoded(imu_sample(0));
  append(stream, false_start);
  append(stream, encoded(imu_sample(1)));
  append(stream, encoded(velocity_estimate(2)));

  Decoder decoder;
  std::vector<Frame> frames;
  decoder.feed(stream, frames);
  EXPECT_EQ(frames, std::vector<Frame>{imu_sample(0)});
  decoder.finish(frames);
  const Decoded whole{frames, decoder.counters()};
  EXPECT_EQ(whole.frames, (std::vector<Frame>{imu_sample(0), imu_sample(1), velocity_estimate(2)}));
  EXPECT_EQ(whole.counters,
            (DecoderCounters{
                .bytes_in = stream.size(), .frames_out = 3, .resyncs = 1, .bytes_discarded = false_start.size()}));
  EXPECT_EQ(harness::first_split_that_differs(Decoder{}, stream, whole), std::nullopt);
}

TEST(ImuFrameDecoder, AccountingIdentityOnTroubledStream) {
  const Bytes stream = troubled_stream();
  const Decoded d = decode(stream, 5);
  EXPECT_EQ(d.counters.bytes_in, stream.size());
  EXPECT_EQ(d.counters.bytes_in, bytes_in_frames(d.frames) + d.counters.bytes_discarded);
}

// crc16_mcrf4xx_fast lives in protocol/crc.cpp; this decoder is its first user.
TEST(Crc16Mcrf4xxFast, MatchesBytewiseForEveryLengthAndSeed) {
  std::mt19937 rng(7);
  Bytes data(100);
  for (auto& b : data) b = static_cast<std::uint8_t>(rng());
  for (std::size_t n = 0; n <= data.size(); ++n) {
    const auto seed = static_cast<std::uint16_t>(rng());
    const std::span<const std::uint8_t> part(data.data(), n);
    ASSERT_EQ(crc16_mcrf4xx_fast(part, seed), crc16_mcrf4xx(part, seed)) << "length " << n;
  }
}

}  // namespace
}  // namespace imubridge::protocol::imu
