#pragma once
// The imubridge IMU frame: our own wire format between the vehicle's IMU board and the ground station.
// Layout, resync rule and counters: docs/protocol.md, section "imubridge IMU frame".
#include <array>
#include <cstddef>
#include <cstdint>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <span>
#include <variant>
#include <vector>

#include "protocol/decoder_counters.hpp"
#include "protocol/stream_scanner.hpp"

namespace imubridge::protocol::imu {

inline constexpr std::uint8_t kSync0 = 0xB7, kSync1 = 0x4D, kVersion = 1;
inline constexpr std::size_t kHeaderSize = 15, kCrcSize = 2;
inline constexpr std::size_t kImuSamplePayloadSize = 20, kVelocityEstimatePayloadSize = 16;
// The longest candidate a decoder may have to wait for: an unknown type with a 255-byte payload.
inline constexpr std::size_t kMaxFrameSize = kHeaderSize + 255 + kCrcSize;

enum class MsgType : std::uint8_t { imu_sample = 0x01, velocity_estimate = 0x02 };

// Raw sensor counts, as the IMU board read them (protocol/calibration.hpp turns them into SI units).
struct ImuRaw {
  std::array<std::int16_t, 3> accel{}, gyro{}, mag{};
  std::int16_t temperature = 0;
  friend bool operator==(const ImuRaw&, const ImuRaw&) = default;
};

// The ground station's horizontal velocity estimate, body frame, sent back to the vehicle.
struct VelocityEstimate {
  float vx = 0, vy = 0, sigma_vx = 0, sigma_vy = 0;  // m/s
  friend bool operator==(const VelocityEstimate&, const VelocityEstimate&) = default;
};

struct Frame {
  std::uint16_t seq = 0;       // as on the wire
  std::uint64_t sequence = 0;  // unwrapped by the decoder (first frame: == seq; +65536 per wrap)
  std::uint64_t device_time_us = 0;
  std::variant<ImuRaw, VelocityEstimate> payload;
  // The sender's restarts the decoder has seen before this frame: device_time_us counts from the last of them.
  std::uint32_t clock_epoch = 0;

  MsgType type() const;
  friend bool operator==(const Frame&, const Frame&) = default;
};

// Bytes `frame` takes on the wire, header and CRC included.
std::size_t encoded_size(const Frame& frame);

// Appends one frame to `out`, numbered frame.seq (frame.sequence is the receiver's business and is not sent).
void encode(const Frame& frame, std::vector<std::uint8_t>& out);

// Streaming decoder for one sender's byte stream. Frames come out in stream order whatever the chunking; a
// candidate whose version, length or CRC is wrong is a false start and the search resumes at the byte after its
// first sync byte, so a frame hidden inside rejected bytes is still found (protocol/stream_scanner.hpp). A frame
// that repeats the sequence number of the one before it is a retransmission and is dropped, so no two emitted frames
// share a Frame::sequence.
class Decoder {
 public:
  // Accepts any chunking (1 byte .. 64 KiB); appends every complete valid frame to `out`.
  void feed(std::span<const std::uint8_t> chunk, std::vector<Frame>& out);
  // End of stream: appends the frames still to be found in the buffered bytes, and counts the rest as discarded.
  void finish(std::vector<Frame>& out);
  const DecoderCounters& counters() const { return scanner_.counters(); }

 private:
  // What is particular to imubridge frames; the rest of decoding is StreamScanner's.
  struct Framing {
    using Finder = StartFinder<kSync0>;
    static constexpr std::size_t kMaxCandidate = kMaxFrameSize;

    Judgement judge(std::span<const std::uint8_t> candidate, bool at_end) const;
    bool take(std::span<const std::uint8_t> frame, std::vector<Frame>& out, DecoderCounters& counters);

    bool have_seq = false;
    std::uint64_t sequence = 0;  // the last frame's, unwrapped (and continued across restarts)
    std::uint16_t seq = 0;       // the last frame's, as on the wire
    // The last frame's time of each message type: a sender may stamp its types from different clocks.
    std::array<std::optional<std::uint64_t>, 2> device_time_us{};
    std::uint32_t clock_epoch = 0;
  };

  StreamScanner<Framing> scanner_;
};

// {"protocol":"imubridge","seq":..,"sequence":..,"type":"imu_sample","device_time_us":..,
//  "accel":[..],"gyro":[..],"mag":[..],"temperature":..}; a velocity estimate carries "vx","vy","sigma_vx","sigma_vy".
void to_json(nlohmann::json& j, const Frame& f);

}  // namespace imubridge::protocol::imu
