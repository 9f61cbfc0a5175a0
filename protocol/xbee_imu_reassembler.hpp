#pragma once
// imubridge IMU frames carried inside XBee RX packets. A vehicle's XBee cuts its IMU byte stream into RF payloads as
// it pleases (a frame split over several packets, several frames in one packet), and packets from several vehicles
// interleave; so each 64-bit source address gets its own IMU decoder, fed that source's payloads in arrival order.
// A sender whose 64-bit address is unknown arrives as 0xFFFFFFFFFFFFFFFF, and all such senders share one decoder.
#include <cstdint>
#include <map>
#include <vector>

#include "protocol/decoder_counters.hpp"
#include "protocol/imu_frame.hpp"
#include "protocol/xbee.hpp"

namespace imubridge::protocol {

class XbeeImuReassembler {
 public:
  struct SourcedFrame {
    std::uint64_t source64 = 0;
    imu::Frame frame;
    friend bool operator==(const SourcedFrame&, const SourcedFrame&) = default;
  };

  // Appends the IMU frames this packet completes, in the order they were sent.
  void on_rx(const xbee::RxPacket& rx, std::vector<SourcedFrame>& out);
  // End of stream for every source: appends the frames each source's decoder still finds in its buffered bytes (in
  // order of source address), and counts the rest as discarded.
  void finish(std::vector<SourcedFrame>& out);
  // Summed over sources; bytes_in counts RF payload bytes.
  DecoderCounters counters() const;
  const std::map<std::uint64_t, imu::Decoder>& sources() const { return sources_; }

 private:
  // Moves the frames a source's decoder left in decoded_ to `out`, tagged with the source.
  void emit(std::uint64_t source64, std::vector<SourcedFrame>& out);

  std::map<std::uint64_t, imu::Decoder> sources_;
  std::vector<imu::Frame> decoded_;  // scratch, kept to reuse its allocation
};

}  // namespace imubridge::protocol
