#include "protocol/xbee.hpp"

#include <algorithm>
#include <nlohmann/json.hpp>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <string>

#include "protocol/hex.hpp"

namespace imubridge::protocol::xbee {
namespace {

constexpr std::uint8_t kEscape = 0x7D;
constexpr std::uint8_t kEscapeXor = 0x20;
constexpr std::uint8_t kXon = 0x11;
constexpr std::uint8_t kXoff = 0x13;

// Fixed fields after the type byte; RX packets and TX requests carry their payload after these.
constexpr std::size_t kRxPacketFields = 8 + 2 + 1;
constexpr std::size_t kTxStatusFields = 1 + 2 + 1 + 1 + 1;
constexpr std::size_t kTxRequestFields = 1 + 8 + 2 + 1 + 1;

// Bytes that API mode 2 sends escaped, wherever they fall after the start delimiter.
constexpr bool is_reserved(std::uint8_t b) { return b == kStartDelimiter || b == kEscape || b == kXon || b == kXoff; }

template <class... Fs>
struct Overloaded : Fs... {
  using Fs::operator()...;
};
template <class... Fs>
Overloaded(Fs...) -> Overloaded<Fs...>;  // clang 14 does not deduce aggregate template arguments by itself

void put_be(std::vector<std::uint8_t>& out, std::uint64_t value, std::size_t bytes) {
  for (std::size_t i = bytes; i-- > 0;) out.push_back(static_cast<std::uint8_t>(value >> (8 * i)));
}

// Reads a big-endian field from the front of `in` and drops it; the caller has checked the size.
std::uint64_t take_be(std::span<const std::uint8_t>& in, std::size_t bytes) {
  std::uint64_t value = 0;
  for (std::size_t i = 0; i < bytes; ++i) value = (value << 8) | in[i];
  in = in.subspan(bytes);
  return value;
}

std::uint8_t take_u8(std::span<const std::uint8_t>& in) { return static_cast<std::uint8_t>(take_be(in, 1)); }
std::uint16_t take_u16(std::span<const std::uint8_t>& in) { return static_cast<std::uint16_t>(take_be(in, 2)); }

// Frame data (type byte first) of a frame, unescaped.
std::vector<std::uint8_t> frame_data(const Frame& frame) {
  std::vector<std::uint8_t> data{frame.frame_type};
  const auto require_type = [&](std::uint8_t type) {
    if (frame.frame_type != type) throw std::invalid_argument("xbee::encode: frame_type does not match the body");
  };
  std::visit(
      Overloaded{[&](const RxPacket& rx) {
                   require_type(kRxPacket);
                   put_be(data, rx.source64, 8);
                   put_be(data, rx.source16, 2);
                   data.push_back(rx.options);
                   data.insert(data.end(), rx.payload.begin(), rx.payload.end());
                 },
                 [&](const TxStatus& st) {
                   require_type(kTxStatus);
                   data.push_back(st.frame_id);
                   put_be(data, st.destination16, 2);
                   data.insert(data.end(), {st.retries, st.delivery_status, st.discovery_status});
                 },
                 [&](const TxRequest& tx) {
                   require_type(kTxRequest);
                   data.push_back(tx.frame_id);
                   put_be(data, tx.destination64, 8);
                   put_be(data, tx.destination16, 2);
                   data.insert(data.end(), {tx.radius, tx.options});
                   data.insert(data.end(), tx.payload.begin(), tx.payload.end());
                 },
                 [&](const OtherFrame& other) { data.insert(data.end(), other.data.begin(), other.data.end()); }},
      frame.body);
  return data;
}

// The inverse of frame_data(); frame data that does not fit its type's layout becomes an OtherFrame.
Frame parse_frame_data(std::span<const std::uint8_t> data) {
  const std::uint8_t type = data[0];
  std::span<const std::uint8_t> in = data.subspan(1);
  if (type == kRxPacket && in.size() >= kRxPacketFields) {
    RxPacket rx;
    rx.source64 = take_be(in, 8);
    rx.source16 = take_u16(in);
    rx.options = take_u8(in);
    rx.payload.assign(in.begin(), in.end());
    return {type, std::move(rx)};
  }
  if (type == kTxStatus && in.size() == kTxStatusFields) {
    TxStatus st;
    st.frame_id = take_u8(in);
    st.destination16 = take_u16(in);
    st.retries = take_u8(in);
    st.delivery_status = take_u8(in);
    st.discovery_status = take_u8(in);
    return {type, st};
  }
  if (type == kTxRequest && in.size() >= kTxRequestFields) {
    TxRequest tx;
    tx.frame_id = take_u8(in);
    tx.destination64 = take_be(in, 8);
    tx.destination16 = take_u16(in);
    tx.radius = take_u8(in);
    tx.options = take_u8(in);
    tx.payload.assign(in.begin(), in.end());
    return {type, std::move(tx)};
  }
  return {type, OtherFrame{{in.begin(), in.end()}}};
}

}  // namespace

std::uint8_t checksum(std::span<const std::uint8_t> frame_data) noexcept {
  return static_cast<std::uint8_t>(0xFF - std::accumulate(frame_data.begin(), frame_data.end(), 0u));
}

void encode(const Frame& frame, ApiMode mode, std::vector<std::uint8_t>& out) {
  const std::vector<std::uint8_t> data = frame_data(frame);
  if (data.size() > kMaxFrameData) throw std::invalid_argument("xbee::encode: frame data exceeds kMaxFrameData");
  const auto put = [&](std::uint8_t b) {
    if (mode == ApiMode::escaped && is_reserved(b)) {
      out.push_back(kEscape);
      b ^= kEscapeXor;
    }
    out.push_back(b);
  };
  out.push_back(kStartDelimiter);
  put(static_cast<std::uint8_t>(data.size() >> 8));
  put(static_cast<std::uint8_t>(data.size()));
  for (std::uint8_t b : data) put(b);
  put(checksum(data));
}

void Decoder::feed(std::span<const std::uint8_t> chunk, std::vector<Frame>& out) { scanner_.feed(chunk, out); }

void Decoder::finish(std::vector<Frame>& out) { scanner_.finish(out); }

// Reads the candidate's length, then its frame data and checksum. Every verdict depends only on bytes already
// received, so the chunking of the stream cannot change it.
inline Judgement Decoder::Framing::judge(std::span<const std::uint8_t> c, bool /*at_end*/) {
  std::size_t wire = 1;  // bytes of the candidate read so far, delimiter included
  std::span<const std::uint8_t> body;
  unescaped.clear();
  if (const auto failed = read_body(c, 2, wire, body)) return {*failed};
  const std::size_t length = std::size_t{body[0]} << 8 | body[1];
  if (length == 0 || length > kMaxFrameData) return {Verdict::false_start};  // bad length
  if (const auto failed = read_body(c, 2 + length + 1, wire, body)) return {*failed};
  frame_data = body.subspan(2, length);
  return {checksum(frame_data) == body.back() ? Verdict::frame : Verdict::bad_crc, wire};
}

// Makes `body` the first `want` bytes after the candidate's delimiter (length, frame data, checksum), unescaped in
// mode 2, and `wire` the bytes they take on the wire with the delimiter; or says why not: need_more, or false_start
// for a bad escape.
std::optional<Verdict> Decoder::Framing::read_body(std::span<const std::uint8_t> c, std::size_t want, std::size_t& wire,
                                                   std::span<const std::uint8_t>& body) {
  if (mode == ApiMode::unescaped) {
    if (c.size() < 1 + want) return Verdict::need_more;
    wire = 1 + want;
    body = c.subspan(1, want);
    return std::nullopt;
  }
  while (unescaped.size() < want) {
    // Runs of bytes that need no unescaping are copied whole.
    const auto first = c.begin() + static_cast<std::ptrdiff_t>(wire);
    const auto last = std::find_if(
        first, first + static_cast<std::ptrdiff_t>(std::min(want - unescaped.size(), c.size() - wire)), is_reserved);
    unescaped.insert(unescaped.end(), first, last);
    wire += static_cast<std::size_t>(last - first);
    if (unescaped.size() == want) break;
    if (wire == c.size()) return Verdict::need_more;
    // A raw 0x7E means this frame was cut short and a new one starts there; a mode-2 device never sends a raw
    // XON/XOFF either; and an escape must stand for one of the four reserved bytes.
    if (c[wire] != kEscape) return Verdict::false_start;
    if (wire + 1 == c.size()) return Verdict::need_more;
    const auto byte = static_cast<std::uint8_t>(c[wire + 1] ^ kEscapeXor);
    if (!is_reserved(byte)) return Verdict::false_start;
    unescaped.push_back(byte);
    wire += 2;
  }
  body = unescaped;
  return std::nullopt;
}

inline bool Decoder::Framing::take(std::span<const std::uint8_t> /*frame*/, std::vector<Frame>& out,
                                   DecoderCounters& counters) {
  const Frame& frame = out.emplace_back(parse_frame_data(frame_data));
  if (std::holds_alternative<OtherFrame>(frame.body)) ++counters.unsupported;
  return true;
}

void to_json(nlohmann::json& j, const Frame& f) {
  j = nlohmann::json{{"protocol", "xbee"}, {"frame_type", f.frame_type}};
  std::visit(Overloaded{[&](const RxPacket& rx) {
                          j["frame_type_name"] = "rx_packet";
                          j["source64"] = hex(rx.source64, 8);
                          j["source16"] = hex(rx.source16, 2);
                          j["options"] = rx.options;
                          j["payload"] = hex(rx.payload);
                        },
                        [&](const TxStatus& st) {
                          j["frame_type_name"] = "tx_status";
                          j["frame_id"] = st.frame_id;
                          j["destination16"] = hex(st.destination16, 2);
                          j["retries"] = st.retries;
                          j["delivery_status"] = st.delivery_status;
                          j["discovery_status"] = st.discovery_status;
                        },
                        [&](const TxRequest& tx) {
                          j["frame_type_name"] = "tx_request";
                          j["frame_id"] = tx.frame_id;
                          j["destination64"] = hex(tx.destination64, 8);
                          j["destination16"] = hex(tx.destination16, 2);
                          j["radius"] = tx.radius;
                          j["options"] = tx.options;
                          j["payload"] = hex(tx.payload);
                        },
                        [&](const OtherFrame& other) {
                          j["frame_type_name"] = "other";
                          j["data"] = hex(other.data);
                        }},
             f.body);
}

}  // namespace imubridge::protocol::xbee
