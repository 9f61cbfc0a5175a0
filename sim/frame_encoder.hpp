#pragma once
// Simulated samples -> the bytes a ground station receives, in any wire format: imubridge frames straight from the
// board, the same frames as a ground XBee delivers them (RX packets, frames split across and sharing packets), or
// MAVLink HIGHRES_IMU (+ ATTITUDE) as a flight controller sends them.
#include <cstdint>
#include <vector>

#include "protocol/wire_format.hpp"
#include "sim/simulator.hpp"

namespace imubridge::sim {

class FrameEncoder {
 public:
  static constexpr std::uint64_t kVehicleRadio = 0x0013A20040A1B2C3;  // the simulated vehicle's XBee
  static constexpr std::size_t kRadioPayload = 48;  // RF payload bytes per packet: frames get split across packets
  static constexpr int kAttitudeEvery = 10;         // MAVLink: one ATTITUDE per this many HIGHRES_IMU

  explicit FrameEncoder(protocol::WireFormat format) : format_(format) {}

  // Appends the bytes the ground station receives after this sample (possibly none, while a radio packet fills).
  void encode(const SimSample& sample, std::vector<std::uint8_t>& out);
  // End of flight: whatever a radio still holds goes out.
  void flush(std::vector<std::uint8_t>& out);

 private:
  void send_radio_packets(std::size_t keep_at_most, std::vector<std::uint8_t>& out);

  protocol::WireFormat format_;
  std::vector<std::uint8_t> radio_pending_;  // imubridge bytes the vehicle's XBee has not sent yet
  std::uint8_t mavlink_seq_ = 0;
};

}  // namespace imubridge::sim
