#pragma once
// Digi XBee API frames, in API mode 1 (unescaped) and API mode 2 (escaped); the layout, the resync rule and the
// counters are described in docs/protocol-xbee.md. IMU frames riding inside RX packets are put back together by
// protocol/xbee_imu_reassembler.hpp.
#include <cstddef>
#include <cstdint>
#include <nlohmann/json_fwd.hpp>
#include <span>
#include <variant>
#include <vector>

#include "protocol/decoder_counters.hpp"

namespace imubridge::protocol::xbee {

enum class ApiMode { unescaped = 1, escaped = 2 };

inline constexpr std::uint8_t kStartDelimiter = 0x7E;
// Largest frame-data length (type byte included) a frame may declare. Real RF payloads are a few hundred bytes, so a
// larger length is corruption: rejecting it at once beats waiting for kilobytes that hide good frames.
inline constexpr std::size_t kMaxFrameData = 1024;

// The API frame types that get a typed body; any other type is carried as OtherFrame.
inline constexpr std::uint8_t kTxRequest = 0x10;
inline constexpr std::uint8_t kTxStatus = 0x8B;
inline constexpr std::uint8_t kRxPacket = 0x90;

struct RxPacket {
  std::uint64_t source64 = 0;
  std::uint16_t source16 = 0;
  std::uint8_t options = 0;
  std::vector<std::uint8_t> payload;
  friend bool operator==(const RxPacket&, const RxPacket&) = default;
};

struct TxStatus {
  std::uint8_t frame_id = 0;
  std::uint16_t destination16 = 0;
  std::uint8_t retries = 0;
  std::uint8_t delivery_status = 0;
  std::uint8_t discovery_status = 0;
  friend bool operator==(const TxStatus&, const TxStatus&) = default;
};

struct TxRequest {
  std::uint8_t frame_id = 0;
  std::uint64_t destination64 = 0;
  std::uint16_t destination16 = 0;
  std::uint8_t radius = 0;
  std::uint8_t options = 0;
  std::vector<std::uint8_t> payload;
  friend bool operator==(const TxRequest&, const TxRequest&) = default;
};

// A frame of a type without a typed body, or of a typed kind whose data is too short (or, for TX status, not exactly
// the right size) to hold its fields. Either way the decoder counts it in `unsupported`.
struct OtherFrame {
  std::vector<std::uint8_t> data;  // frame data after the type byte
  friend bool operator==(const OtherFrame&, const OtherFrame&) = default;
};

struct Frame {
  std::uint8_t frame_type = 0;
  std::variant<RxPacket, TxStatus, TxRequest, OtherFrame> body;
  friend bool operator==(const Frame&, const Frame&) = default;
};

// 0xFF minus the low byte of the sum of the frame data (unescaped, type byte included).
std::uint8_t checksum(std::span<const std::uint8_t> frame_data) noexcept;

// Appends `frame` as it goes on the wire. Throws std::invalid_argument when a typed body comes with another
// frame_type, or when the frame data would exceed kMaxFrameData (the decoder would reject it).
void encode(const Frame& frame, ApiMode mode, std::vector<std::uint8_t>& out);

// Streaming decoder: feed() any chunking of the byte stream and get the same frames and counters. Encoding is
// canonical in both modes, so every emitted frame occupied exactly encode(frame, mode) on the wire.
class Decoder {
 public:
  explicit Decoder(ApiMode mode) : mode_(mode) {}

  void feed(std::span<const std::uint8_t> chunk, std::vector<Frame>& out);
  // End of stream: the bytes of an unfinished frame are counted as discarded, and the decoder starts afresh.
  void finish();
  const DecoderCounters& counters() const { return counters_; }

 private:
  enum class Step { need_more, complete, bad_length, bad_escape, bad_checksum };
  Step scan();
  void copy_plain_run();
  // The complete candidate's frame data: body_ without the length bytes and the checksum.
  std::span<const std::uint8_t> candidate_data() const { return std::span(body_).subspan(2, expected_ - 3); }

  ApiMode mode_;
  DecoderCounters counters_;
  std::vector<std::uint8_t> buf_;  // wire bytes not yet resolved; buf_[0] is a candidate's delimiter if in_frame_
  bool in_frame_ = false;
  std::size_t scanned_ = 0;         // index in buf_ of the candidate's next wire byte
  bool escape_pending_ = false;     // the previous wire byte was the escape 0x7D
  std::size_t expected_ = 0;        // unescaped bytes after the delimiter the candidate needs (0: length unknown)
  std::vector<std::uint8_t> body_;  // the candidate's unescaped bytes after the delimiter: length, data, checksum
};

// {"protocol":"xbee","frame_type":144,"frame_type_name":"rx_packet","source64":"0013A20040A1B2C3","source16":"FFFE",
//  "options":1,"payload":"0102"}; likewise "tx_status", "tx_request", and "other" with its "data". Addresses and byte
// strings are upper-case hex.
void to_json(nlohmann::json& j, const Frame& f);

}  // namespace imubridge::protocol::xbee
