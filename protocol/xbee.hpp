#pragma once
// Digi XBee API frames, in API mode 1 (unescaped) and API mode 2 (escaped); the layout, the resync rule and the
// counters are described in docs/protocol.md, section "XBee API frames". IMU frames riding inside RX packets are put
// back together by protocol/xbee_imu_reassembler.hpp.
#include <cstddef>
#include <cstdint>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <span>
#include <variant>
#include <vector>

#include "protocol/decoder_counters.hpp"
#include "protocol/stream_scanner.hpp"

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

// Streaming decoder: feed() any chunking of the byte stream and get the same frames and counters. A candidate with a
// bad length, escape or checksum is a false start and the search resumes at the byte after its delimiter, so a frame
// that begins inside rejected bytes is still found (protocol/stream_scanner.hpp). Encoding is canonical in both
// modes, so every emitted frame occupied exactly encode(frame, mode) on the wire.
class Decoder {
 public:
  explicit Decoder(ApiMode mode) : scanner_(Framing{mode}) {}

  void feed(std::span<const std::uint8_t> chunk, std::vector<Frame>& out);
  // End of stream: appends the frames still to be found in the buffered bytes, and counts the rest as discarded.
  void finish(std::vector<Frame>& out);
  const DecoderCounters& counters() const { return scanner_.counters(); }

 private:
  // What is particular to XBee API frames; the rest of decoding is StreamScanner's.
  struct Framing {
    using Finder = StartFinder<kStartDelimiter>;
    // The longest candidate: kMaxFrameData bytes of frame data with every byte after the delimiter escaped.
    static constexpr std::size_t kMaxCandidate = 1 + 2 * (2 + kMaxFrameData + 1);

    explicit Framing(ApiMode m) : mode(m) {}

    Judgement judge(std::span<const std::uint8_t> candidate, bool at_end);
    bool take(std::span<const std::uint8_t> frame, std::vector<Frame>& out, DecoderCounters& counters);
    std::optional<Verdict> read_body(std::span<const std::uint8_t> candidate, std::size_t want, std::size_t& wire,
                                     std::span<const std::uint8_t>& body);

    ApiMode mode;
    std::vector<std::uint8_t> unescaped;       // mode 2: the judged candidate after its delimiter, unescaped
    std::span<const std::uint8_t> frame_data;  // of the frame judge() last found valid
  };

  StreamScanner<Framing> scanner_;
};

// {"protocol":"xbee","frame_type":144,"frame_type_name":"rx_packet","source64":"0013A20040A1B2C3","source16":"FFFE",
//  "options":1,"payload":"0102"}; likewise "tx_status", "tx_request", and "other" with its "data". Addresses and byte
// strings are upper-case hex.
void to_json(nlohmann::json& j, const Frame& f);

}  // namespace imubridge::protocol::xbee
