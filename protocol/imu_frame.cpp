#include "protocol/imu_frame.hpp"

#include <algorithm>
#include <bit>
#include <cstring>
#include <nlohmann/json.hpp>
#include <optional>
#include <type_traits>

#include "protocol/crc.hpp"

namespace imubridge::protocol::imu {
namespace {

// Header offsets (docs/protocol.md).
constexpr std::size_t kVersionAt = 2, kTypeAt = 3, kLengthAt = 4, kSeqAt = 5, kTimeAt = 7;

template <typename T>
void put_le(std::vector<std::uint8_t>& out, T value) {
  const auto bits = static_cast<std::make_unsigned_t<T>>(value);
  for (std::size_t i = 0; i < sizeof(T); ++i) out.push_back(static_cast<std::uint8_t>(bits >> (8 * i)));
}

template <typename T>
T get_le(const std::uint8_t* p) {
  std::array<std::uint8_t, sizeof(T)> bytes;
  std::memcpy(bytes.data(), p, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(bytes.begin(), bytes.end());
  return std::bit_cast<T>(bytes);
}

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
    raw.accel[i] = get_le<std::int16_t>(p + 2 * i);
    raw.gyro[i] = get_le<std::int16_t>(p + 6 + 2 * i);
    raw.mag[i] = get_le<std::int16_t>(p + 12 + 2 * i);
  }
  raw.temperature = get_le<std::int16_t>(p + 18);
  return raw;
}

VelocityEstimate read_velocity(const std::uint8_t* p) {
  auto f32 = [p](std::size_t at) { return std::bit_cast<float>(get_le<std::uint32_t>(p + at)); };
  return {f32(0), f32(4), f32(8), f32(12)};
}

// The payload of a CRC-checked frame of a known type.
decltype(Frame::payload) read_payload(const std::uint8_t* frame) {
  const std::uint8_t* payload = frame + kHeaderSize;
  if (static_cast<MsgType>(frame[kTypeAt]) == MsgType::imu_sample) return read_imu(payload);
  return read_velocity(payload);
}

const char* type_name(MsgType type) { return type == MsgType::imu_sample ? "imu_sample" : "velocity_estimate"; }

enum class Verdict { need_more, no_sync, bad_version, bad_length, bad_crc, valid };

// Judges the candidate at `p` from the bytes available so far. Every early verdict depends only on bytes already
// present, so the outcome is the same however the stream was chunked.
Verdict inspect(const std::uint8_t* p, std::size_t avail) {
  if (avail < 2) return Verdict::need_more;
  if (p[1] != kSync1) return Verdict::no_sync;
  if (avail <= kVersionAt) return Verdict::need_more;
  if (p[kVersionAt] != kVersion) return Verdict::bad_version;
  if (avail <= kLengthAt) return Verdict::need_more;
  const std::size_t length = p[kLengthAt];
  if (const auto expected = payload_size(p[kTypeAt]); expected && *expected != length) return Verdict::bad_length;
  const std::size_t size = kHeaderSize + length + kCrcSize;
  if (avail < size) return Verdict::need_more;
  const std::uint16_t crc = crc16_mcrf4xx_fast({p + kVersionAt, size - kCrcSize - kVersionAt});
  return crc == get_le<std::uint16_t>(p + size - kCrcSize) ? Verdict::valid : Verdict::bad_crc;
}

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
  put_le(out, frame.seq);
  put_le(out, frame.device_time_us);
  if (const auto* raw = std::get_if<ImuRaw>(&frame.payload)) {
    for (const auto& axes : {raw->accel, raw->gyro, raw->mag}) {
      for (std::int16_t v : axes) put_le(out, v);
    }
    put_le(out, raw->temperature);
  } else {
    const auto& v = std::get<VelocityEstimate>(frame.payload);
    for (float f : {v.vx, v.vy, v.sigma_vx, v.sigma_vy}) put_le(out, std::bit_cast<std::uint32_t>(f));
  }
  put_le(out, crc16_mcrf4xx_fast(std::span(out).subspan(start + kVersionAt)));
}

void Decoder::feed(std::span<const std::uint8_t> chunk, std::vector<Frame>& out) {
  counters_.bytes_in += chunk.size();
  if (!pending_.empty()) {
    // kMaxFrameSize more bytes always decide the carried-over candidate, so only that much is copied.
    const std::size_t carried = pending_.size();
    const std::size_t take = std::min(chunk.size(), kMaxFrameSize);
    pending_.insert(pending_.end(), chunk.begin(), chunk.begin() + static_cast<std::ptrdiff_t>(take));
    const std::size_t used = scan(pending_, out);
    if (used < carried) {  // undecided: possible only if the whole chunk fit in `take`, so nothing is left over
      pending_.erase(pending_.begin(), pending_.begin() + static_cast<std::ptrdiff_t>(used));
      return;
    }
    pending_.clear();
    chunk = chunk.subspan(used - carried);
  }
  const std::size_t used = scan(chunk, out);
  pending_.assign(chunk.begin() + static_cast<std::ptrdiff_t>(used), chunk.end());
}

void Decoder::finish() {
  counters_.bytes_discarded += pending_.size();
  pending_.clear();
}

std::size_t Decoder::scan(std::span<const std::uint8_t> data, std::vector<Frame>& out) {
  const std::uint8_t* const begin = data.data();
  std::size_t pos = 0;
  while (pos < data.size()) {
    const void* sync = std::memchr(begin + pos, kSync0, data.size() - pos);
    const std::size_t at =
        sync ? static_cast<std::size_t>(static_cast<const std::uint8_t*>(sync) - begin) : data.size();
    counters_.bytes_discarded += at - pos;
    pos = at;
    if (pos == data.size()) break;

    const std::uint8_t* p = begin + pos;
    switch (inspect(p, data.size() - pos)) {
      case Verdict::need_more:
        return pos;
      case Verdict::bad_crc:
        ++counters_.crc_failures;
        [[fallthrough]];
      case Verdict::bad_version:
      case Verdict::bad_length:
        ++counters_.resyncs;
        [[fallthrough]];
      case Verdict::no_sync:  // a lone first sync byte is plain noise, not a false start
        ++counters_.bytes_discarded;
        ++pos;
        break;
      case Verdict::valid: {
        const auto seq = get_le<std::uint16_t>(p + kSeqAt);
        const std::uint64_t sequence = track(seq);  // every well-formed frame used up a number, known type or not
        const std::size_t size = kHeaderSize + p[kLengthAt] + kCrcSize;
        if (payload_size(p[kTypeAt])) {
          Frame& frame = out.emplace_back();  // built in place: via a temporary Frame, decoding ran 2x slower
          frame.seq = seq;
          frame.sequence = sequence;
          frame.device_time_us = get_le<std::uint64_t>(p + kTimeAt);
          frame.payload = read_payload(p);
          ++counters_.frames_out;
        } else {  // a newer sender's message: skipped whole, since it is well formed, but not ours to emit
          ++counters_.unsupported;
          counters_.bytes_discarded += size;
        }
        pos += size;
      }
    }
  }
  return pos;
}

std::uint64_t Decoder::track(std::uint16_t seq) {
  if (!have_seq_) {
    have_seq_ = true;
    return sequence_ = seq;
  }
  // Sequence numbers only move forward, so the step is taken mod 65536 and a repeat reads as a full wrap: the
  // unwrapped sequence stays strictly increasing, so no two frames of one stream share a number.
  const auto step = static_cast<std::uint16_t>(seq - static_cast<std::uint16_t>(sequence_));
  const std::uint64_t advance = step == 0 ? 65536 : step;
  if (advance != 1) {
    ++counters_.sequence_gaps;
    counters_.frames_lost += advance - 1;
  }
  return sequence_ += advance;
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
