#pragma once
// MAVLink v1 and v2 framing: a streaming decoder, an encoder, and the way from a message to the pipeline's Sample.
// Framing, CRC_EXTRA, what is verified and the conversions: docs/protocol.md, section "MAVLink".
#include <array>
#include <cstddef>
#include <cstdint>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "protocol/calibration.hpp"
#include "protocol/decoder_counters.hpp"
#include "protocol/mavlink_messages.hpp"
#include "protocol/sample.hpp"
#include "protocol/stream_scanner.hpp"

namespace imubridge::protocol::mavlink {

inline constexpr std::uint8_t kStxV1 = 0xFE, kStxV2 = 0xFD;
inline constexpr std::uint8_t kIncompatSigned = 0x01;                // the only MAVLink 2 incompat flag defined
inline constexpr std::size_t kHeaderSizeV1 = 6, kHeaderSizeV2 = 10;  // STX included
inline constexpr std::size_t kCrcSize = 2, kSignatureSize = 13;
inline constexpr std::size_t kMaxFrameSize = kHeaderSizeV2 + 255 + kCrcSize + kSignatureSize;

// One frame that passed every check: its id is in the dialects protocol/mavlink_message_specs.cpp knows and its CRC
// verified.
struct Message {
  std::uint8_t version = 2;  // 1 or 2
  std::uint8_t seq = 0, sysid = 0, compid = 0;
  std::uint32_t msgid = 0;                  // 8 bits in MAVLink 1, 24 in MAVLink 2
  std::uint8_t len = 0;                     // payload length as on the wire (a v2 sender may truncate)
  std::array<std::uint8_t, 255> payload{};  // zero-filled beyond len
  bool signed_ = false;                     // v2 signature present (skipped, not verified)
  // The sender's restarts the decoder saw before this message (Decoder); 0 for a message built here.
  std::uint32_t clock_epoch = 0;
  friend bool operator==(const Message&, const Message&) = default;
};

struct FrameOptions {
  std::uint8_t version = 2;  // 1 or 2
  std::uint8_t seq = 0, sysid = 1, compid = 1;
  bool truncate = true;  // v2: drop trailing zero payload bytes, keeping at least one, as MAVLink 2 senders do
  bool sign = false;     // v2: set the signed flag and append a dummy (all-zero) 13-byte signature
};

// A message carrying `payload` as `msgid`. Throws std::invalid_argument for what the wire cannot carry: a payload
// over 255 bytes, or in version 1 an id over 255 or a signature.
Message make_message(std::uint32_t msgid, std::span<const std::uint8_t> payload, const FrameOptions& options);
// A typed message; version 1 carries its base fields only.
Message make_message(const Decoded& message, const FrameOptions& options);

// Appends `m` as a frame. Its CRC takes the CRC_EXTRA of m.msgid, or 0 for an id without one (which no receiver
// can check anyway: Decoder counts such a frame as unverified).
void encode(const Message& m, std::vector<std::uint8_t>& out);

// What the bytes at the start of `bytes` are, judged as Decoder judges a candidate, for a reader that knows where
// frames start (a log of frames, each with its own framing). `size` is the frame's length as its header gives it,
// once the header is whole: for `frame` and `unverified` the bytes the frame takes.
struct FrameCheck {
  enum class Status {
    frame,       // a frame that passed every check
    unverified,  // well formed, but its id has no CRC_EXTRA here, so nothing could check it
    // well formed, but a MAVLink 1 length its id's message (as known here) cannot have: another dialect's or an older
    // version's message of that id, which nothing here can check. A stream's decoder takes it for a false start.
    other_layout,
    bad_crc,    // a known id whose CRC does not match
    malformed,  // no STX, an incompat flag this decoder cannot parse, or a MAVLink 1 length its message cannot have
    cut_short,  // the bytes end before the header or the frame does
  };
  Status status = Status::malformed;
  std::size_t size = 0;
  std::uint32_t msgid = 0;  // once the header is whole
};
FrameCheck check_frame(std::span<const std::uint8_t> bytes);

inline std::optional<Decoded> decode(const Message& m) {
  return decode_payload(m.msgid, std::span(m.payload).first(m.len));
}

// Streaming decoder for one link: frames come out in stream order whatever the chunking. A candidate that fails
// any check is a false start and the search resumes at the byte after its STX, so a frame that begins inside
// rejected bytes is still found (protocol/stream_scanner.hpp). So does a candidate whose id has no CRC_EXTRA, which
// cannot be verified: it is counted as unverified and emits nothing. A frame that repeats the sequence number of
// the one before it from the same component is a retransmission and is dropped.
class Decoder {
 public:
  void feed(std::span<const std::uint8_t> chunk, std::vector<Message>& out);
  // End of stream: a cut-off candidate is a false start, and the search goes on through the bytes after its STX.
  void finish(std::vector<Message>& out);
  const DecoderCounters& counters() const { return scanner_.counters(); }

 private:
  // What is particular to MAVLink; the rest of decoding is StreamScanner's.
  struct Framing {
    using Finder = StartFinder<kStxV1, kStxV2>;
    static constexpr std::size_t kMaxCandidate = kMaxFrameSize;

    Judgement judge(std::span<const std::uint8_t> candidate, bool at_end) const;
    bool take(std::span<const std::uint8_t> frame, std::vector<Message>& out, DecoderCounters& counters);

    // What the decoder remembers of one sending component: its last sequence number and, per timed message kind, its
    // last device time (time_usec, or time_boot_ms in us). A component whose next frame is not the next number and
    // whose clock went back restarted (protocol::is_restart). A link carries a few components: a flat list searched
    // from the last one found costs no allocation and no tree look-up per frame.
    struct Component {
      std::uint16_t id = 0;  // sysid << 8 | compid
      std::uint8_t last_seq = 0;
      std::array<std::uint64_t, kClockSlots> last_time_us{};
      std::array<bool, kClockSlots> has_time{};
    };
    std::vector<Component> components;
    std::size_t last_found = 0;
    std::uint32_t clock_epoch = 0;
  };

  StreamScanner<Framing> scanner_;
};

// {"protocol":"mavlink","version":2,"seq":..,"sysid":..,"compid":..,"msgid":105,"len":63,"signed":false,
//  "name":"HIGHRES_IMU", then the decoded fields by their MAVLink names}; other ids carry "payload" as upper-case
// hex instead of a name and fields.
void to_json(nlohmann::json& j, const Message& m);

// HIGHRES_IMU, SCALED_IMU, SCALED_IMU2, SCALED_IMU3, and RAW_IMU given the IMU's calibration, as a Sample in SI
// units; nothing for other messages (ATTITUDE included) or for RAW_IMU without a calibration. seq is the 8-bit wire
// number; source and recv_mono_ns are the caller's to fill.
std::optional<Sample> to_sample(const Message& m, const Calibration* raw_calibration);

// Which IMU a message to_sample converts measures: its sender (system and component), its message (SCALED_IMU,
// SCALED_IMU2 and SCALED_IMU3 are an autopilot's first, second and third IMU) and, for HIGHRES_IMU and RAW_IMU, which
// carry the IMUs of a sender in one message, their `id` field. A link that interleaved two of them would give one
// sample stream of two sensors; pipeline::LinkDecoder can keep one (docs/replay.md, "MAVLink telemetry logs").
struct ImuSource {
  std::uint32_t msgid = 0;
  std::uint8_t sysid = 0, compid = 0;
  std::uint8_t id = 0;  // HIGHRES_IMU's and RAW_IMU's id field; 0 for the SCALED_IMUs
  friend auto operator<=>(const ImuSource&, const ImuSource&) = default;
};
// The IMU `m` measures; nothing for a message that is not an IMU message to_sample converts.
std::optional<ImuSource> imu_source(const Message& m);
// "SCALED_IMU2 from system 1, component 1", "HIGHRES_IMU id 1 from system 1, component 1".
std::string describe(const ImuSource& source);

}  // namespace imubridge::protocol::mavlink
