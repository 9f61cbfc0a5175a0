#include "protocol/imu_frame.hpp"

#include <nlohmann/json.hpp>
#include <optional>

#include "protocol/byte_order.hpp"
#include "protocol/crc.hpp"

namespace imubridge::protocol::imu {
namespace {

// Header offsets (docs/protocol.md).
constexpr std::size_t kVersionAt = 2, kTypeAt = 3, kLengthAt = 4, kSeqAt = 5, kTimeAt = 7;

std::optional<std::size_t> payload_size(std::uint8_t type) {
  switch (static_cast<MsgType>(type)) {
    case MsgType::imu_sample:
      return kImuSamplePayloadSize;
    case MsgType::velocity_estimate:
      return kVelocityEstimatePayloadSize;
  }
  return std::nullopt;
}

ImuRaw read_imu(const std::uint8_t* p) {
  ImuRaw raw;
  for (std::size_t i = 0; i < 3; ++i) {
    raw.accel[i] = load_le<std::int16_t>(p + 2 * i);
    raw.gyro[i] = load_le<std::int16_t>(p + 6 + 2 * i);
    raw.mag[i] = load_le<std::int16_t>(p + 12 + 2 * i);
  }
  raw.temperature = load_le<std::int16_t>(p + 18);
  return raw;
}

VelocityEstimate read_velocity(const std::uint8_t* p) {
  return {load_le<float>(p), load_le<float>(p + 4), load_le<float>(p + 8), load_le<float>(p + 12)};
}

// The payload of a CRC-checked frame of a known type.
decltype(Frame::payload) read_payload(const std::uint8_t* frame) {
  const std::uint8_t* payload = frame + kHeaderSize;
  if (static_cast<MsgType>(frame[kTypeAt]) == MsgType::imu_sample) return read_imu(payload);
  return read_velocity(payload);
}

const char* type_name(MsgType type) { return type == MsgType::imu_sample ? "imu_sample" : "velocity_estimate"; }

}  // namespace

MsgType Frame::type() const {
  return std::holds_alternative<ImuRaw>(payload) ? MsgType::imu_sample : MsgType::velocity_estimate;
}

std::size_t encoded_size(const Frame& frame) {
  return kHeaderSize + *payload_size(static_cast<std::uint8_t>(frame.type())) + kCrcSize;
}

void encode(const Frame& frame, std::vector<std::uint8_t>& out) {
  const std::size_t start = out.size();
  out.insert(out.end(), {kSync0, kSync1, kVersion, static_cast<std::uint8_t>(frame.type()),
                         static_cast<std::uint8_t>(encoded_size(frame) - kHeaderSize - kCrcSize)});
  append_le(out, frame.seq);
  append_le(out, frame.device_time_us);
  if (const auto* raw = std::get_if<ImuRaw>(&frame.payload)) {
    for (const auto& axes : {raw->accel, raw->gyro, raw->mag}) {
      for (std::int16_t v : axes) append_le(out, v);
    }
    append_le(out, raw->temperature);
  } else {
    const auto& v = std::get<VelocityEstimate>(frame.payload);
    for (float f : {v.vx, v.vy, v.sigma_vx, v.sigma_vy}) append_le(out, f);
  }
  append_le(out, crc16_mcrf4xx_fast(std::span(out).subspan(start + kVersionAt)));
}

void Decoder::feed(std::span<const std::uint8_t> chunk, std::vector<Frame>& out) { scanner_.feed(chunk, out); }

void Decoder::finish(std::vector<Frame>& out) { scanner_.finish(out); }

// Every early verdict depends only on bytes already present, so the outcome is the same however the stream was
// chunked.
inline Judgement Decoder::Framing::judge(std::span<const std::uint8_t> c, bool /*at_end*/) const {
  if (c.size() < 2) return {Verdict::need_more};
  if (c[1] != kSync1) return {Verdict::noise};  // a lone first sync byte is plain noise, not a false start
  if (c.size() <= kVersionAt) return {Verdict::need_more};
  if (c[kVersionAt] != kVersion) return {Verdict::false_start};  // bad version
  if (c.size() <= kLengthAt) return {Verdict::need_more};
  const std::size_t length = c[kLengthAt];
  if (const auto expected = payload_size(c[kTypeAt]); expected && *expected != length) return {Verdict::false_start};
  const std::size_t size = kHeaderSize + length + kCrcSize;
  if (c.size() < size) return {Verdict::need_more};
  const std::uint16_t crc = crc16_mcrf4xx_fast(c.subspan(kVersionAt, size - kCrcSize - kVersionAt));
  return {crc == load_le<std::uint16_t>(&c[size - kCrcSize]) ? Verdict::frame : Verdict::bad_crc, size};
}

inline bool Decoder::Framing::take(std::span<const std::uint8_t> f, std::vector<Frame>& out,
                                   DecoderCounters& counters) {
  // Every well-formed frame uses up a sequence number, known type or not.
  const auto wire_seq = load_le<std::uint16_t>(&f[kSeqAt]);
  const auto time_us = load_le<std::uint64_t>(&f[kTimeAt]);
  const std::size_t type_index = f[kTypeAt] - 1u;  // imu_sample 1, velocity_estimate 2
  std::optional<std::uint64_t>* last_time = type_index < device_time_us.size() ? &device_time_us[type_index] : nullptr;
  if (!have_seq) {
    have_seq = true;
    sequence = wire_seq;
  } else if (last_time && *last_time && is_restart(seq, wire_seq, **last_time, time_us)) {
    // A sender numbers its frames from 0 after it boots: the ones before `wire_seq` since then are lost. Those it
    // sent before the restart and we never saw cannot be known, and unwrapping the step back would invent ~65,000.
    ++counters.device_restarts;
    counters.frames_lost += wire_seq;
    if (wire_seq > 0) ++counters.sequence_gaps;
    sequence += static_cast<std::uint64_t>(wire_seq) + 1;
    ++clock_epoch;
    device_time_us.fill(std::nullopt);  // every type's times are on the new clock now
  } else {
    const std::uint16_t step = count_sequence_step(seq, wire_seq, counters);
    if (step == 0) return false;  // sent again: the frame before it was this one
    sequence += step;
  }
  seq = wire_seq;
  if (last_time) *last_time = time_us;
  if (!payload_size(f[kTypeAt])) {  // a newer sender's message: well formed, but not ours to emit
    ++counters.unsupported;
    return false;
  }
  Frame& frame = out.emplace_back();  // built in place: via a temporary Frame, decoding ran 2x slower
  frame.seq = wire_seq;
  frame.sequence = sequence;
  frame.device_time_us = time_us;
  frame.clock_epoch = clock_epoch;
  frame.payload = read_payload(f.data());
  return true;
}

void to_json(nlohmann::json& j, const Frame& f) {
  j = nlohmann::json{{"protocol", "imubridge"},
                     {"seq", f.seq},
                     {"sequence", f.sequence},
                     {"type", type_name(f.type())},
                     {"device_time_us", f.device_time_us}};
  if (const auto* raw = std::get_if<ImuRaw>(&f.payload)) {
    j["accel"] = raw->accel;
    j["gyro"] = raw->gyro;
    j["mag"] = raw->mag;
    j["temperature"] = raw->temperature;
  } else {
    const auto& v = std::get<VelocityEstimate>(f.payload);
    j["vx"] = v.vx;
    j["vy"] = v.vy;
    j["sigma_vx"] = v.sigma_vx;
    j["sigma_vy"] = v.sigma_vy;
  }
}

}  // namespace imubridge::protocol::imu
