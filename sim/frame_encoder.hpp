#pragma once
// Simulated samples -> the bytes a ground station receives, in any wire format: imubridge frames straight from the
// board, the same frames as a ground XBee delivers them (RX packets, frames split across and sharing packets), or
// MAVLink HIGHRES_IMU (+ ATTITUDE) as a flight controller sends them.
#include <cstdint>
#include <vector>

#include "protocol/mavlink_messages.hpp"
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

// A flight controller's MAVLink telemetry as a ground station logs it, frame by frame (`imubridge sim --tlog`): the
// HIGHRES_IMU of every sample and the ATTITUDE of every kAttitudeEvery-th, as FrameEncoder sends them, and with each
// ATTITUDE a LOCAL_POSITION_NED of the truth (the mass centre's position and velocity, NED), so an import of the log
// finds the trajectory the simulator flew. One sender, system 1 component 1, numbering its frames in one sequence.
class MavlinkTelemetry {
 public:
  // Appends the frames this sample makes, each whole, to `frames`.
  void encode(const SimSample& sample, std::vector<std::vector<std::uint8_t>>& frames);
  // `message` as the sender's next frame (MAVLink 2).
  std::vector<std::uint8_t> frame(const protocol::mavlink::Decoded& message);

 private:
  std::uint8_t seq_ = 0;
};

}  // namespace imubridge::sim
