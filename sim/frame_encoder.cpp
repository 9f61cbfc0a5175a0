#include "sim/frame_encoder.hpp"

#include <algorithm>
#include <cmath>

#include "protocol/imu_frame.hpp"
#include "protocol/mavlink.hpp"
#include "protocol/xbee.hpp"

namespace imubridge::sim {
namespace {

protocol::imu::Frame imu_frame(const SimSample& sample) {
  protocol::imu::Frame frame;
  frame.seq = static_cast<std::uint16_t>(sample.index);
  frame.device_time_us = static_cast<std::uint64_t>(std::llround(sample.time_s * 1e6));
  frame.payload = sample.raw;
  return frame;
}

protocol::mavlink::HighresImu highres_imu(const SimSample& sample) {
  const auto& m = sample.measured;
  protocol::mavlink::HighresImu imu;
  imu.time_usec = static_cast<std::uint64_t>(std::llround(sample.time_s * 1e6));
  imu.xacc = static_cast<float>(m.accel.x()), imu.yacc = static_cast<float>(m.accel.y());
  imu.zacc = static_cast<float>(m.accel.z());
  imu.xgyro = static_cast<float>(m.gyro.x()), imu.ygyro = static_cast<float>(m.gyro.y());
  imu.zgyro = static_cast<float>(m.gyro.z());
  imu.xmag = static_cast<float>(m.mag.x() / 100.0), imu.ymag = static_cast<float>(m.mag.y() / 100.0);  // uT->G
  imu.zmag = static_cast<float>(m.mag.z() / 100.0);
  imu.temperature = static_cast<float>(m.temperature_c);
  imu.fields_updated = 0x1FF | (1u << 12);  // accel, gyro, mag, temperature
  return imu;
}

std::uint32_t time_boot_ms(const SimSample& sample) {
  return static_cast<std::uint32_t>(std::llround(sample.time_s * 1e3));
}

protocol::mavlink::Attitude attitude(const SimSample& sample) {
  const auto& truth = sample.truth;
  protocol::mavlink::Attitude attitude;
  attitude.time_boot_ms = time_boot_ms(sample);
  attitude.roll = static_cast<float>(truth.euler.x()), attitude.pitch = static_cast<float>(truth.euler.y());
  attitude.yaw = static_cast<float>(truth.euler.z());
  attitude.rollspeed = static_cast<float>(truth.omega.x()), attitude.pitchspeed = static_cast<float>(truth.omega.y());
  attitude.yawspeed = static_cast<float>(truth.omega.z());
  return attitude;
}

protocol::mavlink::LocalPositionNed local_position(const SimSample& sample) {
  const auto& p = sample.truth.position_ned;
  const auto& v = sample.truth.velocity_ned;
  return {.time_boot_ms = time_boot_ms(sample),
          .x = static_cast<float>(p.x()),
          .y = static_cast<float>(p.y()),
          .z = static_cast<float>(p.z()),
          .vx = static_cast<float>(v.x()),
          .vy = static_cast<float>(v.y()),
          .vz = static_cast<float>(v.z())};
}

bool sends_attitude(const SimSample& sample) { return sample.index % FrameEncoder::kAttitudeEvery == 0; }

void encode_mavlink(const SimSample& sample, std::uint8_t& seq, std::vector<std::uint8_t>& out) {
  namespace mav = protocol::mavlink;
  mav::encode(mav::make_message(highres_imu(sample), {.seq = seq++}), out);
  if (sends_attitude(sample)) mav::encode(mav::make_message(attitude(sample), {.seq = seq++}), out);
}

}  // namespace

void FrameEncoder::encode(const SimSample& sample, std::vector<std::uint8_t>& out) {
  switch (format_) {
    case protocol::WireFormat::imubridge:
      protocol::imu::encode(imu_frame(sample), out);
      return;
    case protocol::WireFormat::xbee:
    case protocol::WireFormat::xbee_escaped:
      protocol::imu::encode(imu_frame(sample), radio_pending_);
      send_radio_packets(kRadioPayload - 1, out);  // full packets only; the rest waits for the next sample
      return;
    case protocol::WireFormat::mavlink:
      encode_mavlink(sample, mavlink_seq_, out);
      return;
  }
}

void FrameEncoder::flush(std::vector<std::uint8_t>& out) { send_radio_packets(0, out); }

void FrameEncoder::send_radio_packets(std::size_t keep_at_most, std::vector<std::uint8_t>& out) {
  const auto mode = format_ == protocol::WireFormat::xbee_escaped ? protocol::xbee::ApiMode::escaped
                                                                   : protocol::xbee::ApiMode::unescaped;
  std::size_t sent = 0;
  while (radio_pending_.size() - sent > keep_at_most && sent < radio_pending_.size()) {
    const std::size_t n = std::min(kRadioPayload, radio_pending_.size() - sent);
    protocol::xbee::RxPacket rx{.source64 = kVehicleRadio, .source16 = 0x0001, .options = 0x01, .payload = {}};
    rx.payload.assign(radio_pending_.begin() + static_cast<std::ptrdiff_t>(sent),
                      radio_pending_.begin() + static_cast<std::ptrdiff_t>(sent + n));
    protocol::xbee::encode({protocol::xbee::kRxPacket, std::move(rx)}, mode, out);
    sent += n;
  }
  radio_pending_.erase(radio_pending_.begin(), radio_pending_.begin() + static_cast<std::ptrdiff_t>(sent));
}

void MavlinkTelemetry::encode(const SimSample& sample, std::vector<std::vector<std::uint8_t>>& frames) {
  frames.push_back(frame(highres_imu(sample)));
  if (sends_attitude(sample)) {
    frames.push_back(frame(attitude(sample)));
    frames.push_back(frame(local_position(sample)));
  }
}

std::vector<std::uint8_t> MavlinkTelemetry::frame(const protocol::mavlink::Decoded& message) {
  std::vector<std::uint8_t> out;
  protocol::mavlink::encode(protocol::mavlink::make_message(message, {.seq = seq_++}), out);
  return out;
}

}  // namespace imubridge::sim
