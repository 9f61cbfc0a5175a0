#include "protocol/xbee_imu_reassembler.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstddef>
#include <nlohmann/json.hpp>
#include <ostream>
#include <span>
#include <vector>

#include "tests/support/decoder_harness.hpp"

namespace imubridge::protocol {

// Readable failure messages for the EXPECT_EQs below.
namespace imu {
void PrintTo(const Frame& f, std::ostream* os) { *os << nlohmann::json(f).dump(); }
}  // namespace imu

namespace {

using Bytes = std::vector<std::uint8_t>;
constexpr std::uint64_t kVehicleA = 0x0013A20040A1B2C3;
constexpr std::uint64_t kVehicleB = 0x0013A20040D4E5F6;

// IMU samples numbered from 0, as the decoder reports them (sequence == seq until the counter wraps).
std::vector<imu::Frame> imu_frames(std::size_t count, std::int16_t base) {
  std::vector<imu::Frame> frames;
  for (std::size_t i = 0; i < count; ++i) {
    const auto n = static_cast<std::int16_t>(base + i);
    imu::ImuRaw raw{.accel = {n, 2, 3}, .gyro = {4, n, 6}, .mag = {7, 8, n}, .temperature = 25};
    frames.push_back({.seq = static_cast<std::uint16_t>(i), .sequence = i, .device_time_us = 1000 * i, .payload = raw});
  }
  return frames;
}

Bytes imu_stream(const std::vector<imu::Frame>& frames) {
  Bytes stream;
  for (const imu::Frame& f : frames) imu::encode(f, stream);
  return stream;
}

// Cuts `stream` into RX packets from `source64` with payloads of the given sizes, cycling through them.
std::vector<xbee::RxPacket> packets(std::uint64_t source64, const Bytes& stream, std::vector<std::size_t> sizes) {
  std::vector<xbee::RxPacket> out;
  for (std::size_t pos = 0, i = 0; pos < stream.size(); ++i) {
    const std::size_t n = std::min(sizes[i % sizes.size()], stream.size() - pos);
    out.push_back({source64, 0xFFFE, 0x01, Bytes(stream.begin() + pos, stream.begin() + pos + n)});
    pos += n;
  }
  return out;
}

std::vector<imu::Frame> frames_from(std::uint64_t source64, const std::vector<XbeeImuReassembler::SourcedFrame>& out) {
  std::vector<imu::Frame> frames;
  for (const auto& sf : out) {
    if (sf.source64 == source64) frames.push_back(sf.frame);
  }
  return frames;
}

TEST(XbeeImuReassembler, FramesSplitAcrossPackets) {
  const auto frames = imu_frames(5, 100);
  const Bytes stream = imu_stream(frames);
  XbeeImuReassembler reassembler;
  std::vector<XbeeImuReassembler::SourcedFrame> out;
  // Cuts fall inside headers, payloads and CRCs; one packet carries a single byte.
  for (const auto& rx : packets(kVehicleA, stream, {1, 10, 36, 2, 50, 86})) reassembler.on_rx(rx, out);
  reassembler.finish(out);
  EXPECT_EQ(frames_from(kVehicleA, out), frames);
  EXPECT_EQ(out.size(), frames.size());
  EXPECT_EQ(reassembler.counters(), (DecoderCounters{.bytes_in = stream.size(), .frames_out = 5}));
}

TEST(XbeeImuReassembler, SeveralFramesPerPacket) {
  const auto frames = imu_frames(6, 100);
  const Bytes stream = imu_stream(frames);
  XbeeImuReassembler reassembler;
  std::vector<XbeeImuReassembler::SourcedFrame> out;
  const auto rxs = packets(kVehicleA, stream, {3 * imu::encoded_size(frames[0])});
  ASSERT_EQ(rxs.size(), 2u);
  reassembler.on_rx(rxs[0], out);
  EXPECT_EQ(out.size(), 3u);  // a packet's frames come out as soon as it arrives
  reassembler.on_rx(rxs[1], out);
  EXPECT_EQ(frames_from(kVehicleA, out), frames);
  EXPECT_EQ(reassembler.counters(), (DecoderCounters{.bytes_in = stream.size(), .frames_out = 6}));
}

TEST(XbeeImuReassembler, TwoVehiclesInterleavedOverEscapedXbee) {
  const auto frames_a = imu_frames(4, 100), frames_b = imu_frames(4, -200);
  const auto rx_a = packets(kVehicleA, imu_stream(frames_a), {25});
  const auto rx_b = packets(kVehicleB, imu_stream(frames_b), {30, 14});
  Bytes wire;
  for (std::size_t i = 0; i < std::max(rx_a.size(), rx_b.size()); ++i) {
    if (i < rx_a.size()) xbee::encode({xbee::kRxPacket, rx_a[i]}, xbee::ApiMode::escaped, wire);
    if (i < rx_b.size()) xbee::encode({xbee::kRxPacket, rx_b[i]}, xbee::ApiMode::escaped, wire);
  }

  // The whole receive path, one serial byte at a time.
  xbee::Decoder decoder(xbee::ApiMode::escaped);
  XbeeImuReassembler reassembler;
  std::vector<xbee::Frame> xbee_frames;
  std::vector<XbeeImuReassembler::SourcedFrame> out;
  for (std::uint8_t byte : wire) {
    decoder.feed(std::span(&byte, 1), xbee_frames);
    for (const xbee::Frame& f : xbee_frames) reassembler.on_rx(std::get<xbee::RxPacket>(f.body), out);
    xbee_frames.clear();
  }
  EXPECT_EQ(frames_from(kVehicleA, out), frames_a);
  EXPECT_EQ(frames_from(kVehicleB, out), frames_b);
  EXPECT_EQ(out.size(), 8u);
  ASSERT_EQ(reassembler.sources().size(), 2u);
  for (const auto& [source64, imu_decoder] : reassembler.sources()) {
    EXPECT_EQ(imu_decoder.counters().frames_out, 4u) << std::hex << source64;
    EXPECT_EQ(imu_decoder.counters().bytes_discarded, 0u) << std::hex << source64;
  }
}

TEST(XbeeImuReassembler, LostPacketHurtsOnlyItsOwnVehicle) {
  const auto frames_a = imu_frames(5, 100), frames_b = imu_frames(5, -200);
  const std::size_t frame_size = imu::encoded_size(frames_a[0]);
  auto rx_a = packets(kVehicleA, imu_stream(frames_a), {frame_size + 5});
  const auto rx_b = packets(kVehicleB, imu_stream(frames_b), {frame_size + 5});
  // A's second packet holds the end of frame 1 and the start of frame 2 (with its sync bytes): both are lost.
  rx_a.erase(rx_a.begin() + 1);

  XbeeImuReassembler reassembler;
  std::vector<XbeeImuReassembler::SourcedFrame> out;
  for (std::size_t i = 0; i < rx_b.size(); ++i) {
    if (i < rx_a.size()) reassembler.on_rx(rx_a[i], out);
    reassembler.on_rx(rx_b[i], out);
  }
  reassembler.finish(out);

  EXPECT_EQ(frames_from(kVehicleA, out), (std::vector{frames_a[0], frames_a[3], frames_a[4]}));
  EXPECT_EQ(frames_from(kVehicleB, out), frames_b);
  const DecoderCounters& a = reassembler.sources().at(kVehicleA).counters();
  EXPECT_EQ(a.sequence_gaps, 1u);
  EXPECT_EQ(a.frames_lost, 2u);
  EXPECT_EQ(a.bytes_in, 3 * frame_size + a.bytes_discarded);
  EXPECT_EQ(reassembler.sources().at(kVehicleB).counters(),
            (DecoderCounters{.bytes_in = 5 * frame_size, .frames_out = 5}));
}

TEST(XbeeImuReassembler, FinishCountsUnfinishedFramesAndSumsSources) {
  const auto frames = imu_frames(2, 100);
  const Bytes stream = imu_stream(frames);
  const std::size_t frame_size = imu::encoded_size(frames[0]);
  const Bytes one_and_a_half(stream.begin(), stream.begin() + static_cast<std::ptrdiff_t>(frame_size + 18));

  XbeeImuReassembler reassembler;
  std::vector<XbeeImuReassembler::SourcedFrame> out;
  reassembler.on_rx({kVehicleA, 0xFFFE, 0x01, one_and_a_half}, out);
  reassembler.on_rx({kVehicleB, 0xFFFE, 0x01, stream}, out);
  reassembler.finish(out);
  EXPECT_EQ(out.size(), 3u);
  // A's half frame is cut off by the end of the stream: a false start.
  EXPECT_EQ(
      reassembler.counters(),
      (DecoderCounters{
          .bytes_in = one_and_a_half.size() + stream.size(), .frames_out = 3, .resyncs = 1, .bytes_discarded = 18}));
}

TEST(XbeeImuReassembler, FinishEmitsWhatEachSourceStillFinds) {
  // Vehicle A's last packet starts with a corrupted IMU header claiming a 255-byte payload, over a real frame: only the
  // end of the stream refutes the claim, so that frame comes out of finish(), tagged with A.
  const auto frames = imu_frames(2, 100);
  Bytes last_packet = {imu::kSync0, imu::kSync1, imu::kVersion, 0x7F, 0xFF};
  imu::encode(frames[1], last_packet);

  XbeeImuReassembler reassembler;
  std::vector<XbeeImuReassembler::SourcedFrame> out;
  reassembler.on_rx({kVehicleB, 0xFFFE, 0x01, imu_stream({frames[0]})}, out);
  reassembler.on_rx({kVehicleA, 0xFFFE, 0x01, last_packet}, out);
  EXPECT_EQ(out, (std::vector<XbeeImuReassembler::SourcedFrame>{{kVehicleB, frames[0]}}));
  reassembler.finish(out);
  EXPECT_EQ(out, (std::vector<XbeeImuReassembler::SourcedFrame>{{kVehicleB, frames[0]}, {kVehicleA, frames[1]}}));
  EXPECT_EQ(reassembler.sources().at(kVehicleA).counters(),
            (DecoderCounters{.bytes_in = last_packet.size(), .frames_out = 1, .resyncs = 1, .bytes_discarded = 5}));
}

TEST(XbeeImuReassembler, RetransmittedPacketIsCountedAsDuplicates) {
  // The sending radio did not get its acknowledgement and sent packet 1 again; the receiver got both copies.
  const auto frames = imu_frames(3, 100);
  const auto rxs = packets(kVehicleA, imu_stream(frames), {imu::encoded_size(frames[0])});
  ASSERT_EQ(rxs.size(), 3u);

  XbeeImuReassembler reassembler;
  std::vector<XbeeImuReassembler::SourcedFrame> out;
  for (const xbee::RxPacket& rx : {rxs[0], rxs[1], rxs[1], rxs[2]}) reassembler.on_rx(rx, out);
  reassembler.finish(out);
  EXPECT_EQ(frames_from(kVehicleA, out), frames);
  const std::size_t frame_size = imu::encoded_size(frames[0]);
  EXPECT_EQ(
      reassembler.counters(),
      (DecoderCounters{.bytes_in = 4 * frame_size, .frames_out = 3, .bytes_discarded = frame_size, .duplicates = 1}));
}

}  // namespace
}  // namespace imubridge::protocol
