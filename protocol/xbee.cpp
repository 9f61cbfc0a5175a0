#include "protocol/xbee.hpp"

#include <algorithm>
#include <cstring>
#include <nlohmann/json.hpp>
#include <numeric>
#include <stdexcept>
#include <string>

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

void append_hex(std::string& s, std::uint8_t byte) {
  static constexpr char kDigits[] = "0123456789ABCDEF";
  s += kDigits[byte >> 4];
  s += kDigits[byte & 0xF];
}

std::string hex(std::span<const std::uint8_t> bytes) {
  std::string s;
  for (std::uint8_t b : bytes) append_hex(s, b);
  return s;
}

std::string hex_be(std::uint64_t value, std::size_t bytes) {
  std::string s;
  for (std::size_t i = bytes; i-- > 0;) append_hex(s, static_cast<std::uint8_t>(value >> (8 * i)));
  return s;
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

void Decoder::feed(std::span<const std::uint8_t> chunk, std::vector<Frame>& out) {
  counters_.bytes_in += chunk.size();
  buf_.insert(buf_.end(), chunk.begin(), chunk.end());
  std::size_t head = 0;  // buf_[0, head) is resolved: part of an emitted frame or counted as discarded
  for (;;) {
    if (!in_frame_) {
      const void* found = head < buf_.size() ? std::memchr(&buf_[head], kStartDelimiter, buf_.size() - head) : nullptr;
      const std::size_t start = found ? static_cast<const std::uint8_t*>(found) - buf_.data() : buf_.size();
      counters_.bytes_discarded += start - head;
      head = start;
      if (head == buf_.size()) break;
      in_frame_ = true;
      scanned_ = head + 1;
      escape_pending_ = false;
      expected_ = 0;
      body_.clear();
    }
    const Step step = scan();
    if (step == Step::need_more) break;
    in_frame_ = false;
    if (step == Step::complete) {
      out.push_back(parse_frame_data(candidate_data()));
      ++counters_.frames_out;
      if (std::holds_alternative<OtherFrame>(out.back().body)) ++counters_.unsupported;
      head = scanned_;
    } else {
      // A false start gives up only its delimiter: the search resumes at the next byte, so a frame that begins
      // inside the rejected bytes is still found.
      ++counters_.resyncs;
      if (step == Step::bad_checksum) ++counters_.crc_failures;
      ++counters_.bytes_discarded;
      ++head;
    }
  }
  buf_.erase(buf_.begin(), buf_.begin() + static_cast<std::ptrdiff_t>(head));
  if (in_frame_) scanned_ -= head;
}

void Decoder::finish() {
  counters_.bytes_discarded += buf_.size();
  buf_.clear();
  in_frame_ = false;
}

// Advances the candidate at buf_[0] over the buffered wire bytes, unescaping them into body_.
Decoder::Step Decoder::scan() {
  while (scanned_ < buf_.size()) {
    std::uint8_t byte = buf_[scanned_++];
    if (mode_ == ApiMode::escaped) {
      if (escape_pending_) {
        escape_pending_ = false;
        byte ^= kEscapeXor;
        if (!is_reserved(byte)) return Step::bad_escape;
      } else if (byte == kEscape) {
        escape_pending_ = true;
        continue;
      } else if (is_reserved(byte)) {
        // A raw 0x7E means this frame was cut short and a new one starts there; a mode-2 device never sends a raw
        // XON/XOFF either.
        return Step::bad_escape;
      }
    }
    body_.push_back(byte);
    if (expected_ == 0) {
      if (body_.size() < 2) continue;
      const std::size_t length = std::size_t{body_[0]} << 8 | body_[1];
      if (length == 0 || length > kMaxFrameData) return Step::bad_length;
      expected_ = 2 + length + 1;
    } else if (body_.size() == expected_) {
      return checksum(candidate_data()) == body_.back() ? Step::complete : Step::bad_checksum;
    }
    copy_plain_run();
  }
  return Step::need_more;
}

// Frame-data bytes that need no escape handling need no byte-at-a-time loop either: copies the buffered run of them,
// stopping short of the checksum byte and, in mode 2, of the next reserved byte.
void Decoder::copy_plain_run() {
  const auto first = buf_.begin() + static_cast<std::ptrdiff_t>(scanned_);
  auto last = first + static_cast<std::ptrdiff_t>(std::min(expected_ - body_.size() - 1, buf_.size() - scanned_));
  if (mode_ == ApiMode::escaped) last = std::find_if(first, last, is_reserved);
  body_.insert(body_.end(), first, last);
  scanned_ += static_cast<std::size_t>(last - first);
}

void to_json(nlohmann::json& j, const Frame& f) {
  j = nlohmann::json{{"protocol", "xbee"}, {"frame_type", f.frame_type}};
  std::visit(Overloaded{[&](const RxPacket& rx) {
                          j["frame_type_name"] = "rx_packet";
                          j["source64"] = hex_be(rx.source64, 8);
                          j["source16"] = hex_be(rx.source16, 2);
                          j["options"] = rx.options;
                          j["payload"] = hex(rx.payload);
                        },
                        [&](const TxStatus& st) {
                          j["frame_type_name"] = "tx_status";
                          j["frame_id"] = st.frame_id;
                          j["destination16"] = hex_be(st.destination16, 2);
                          j["retries"] = st.retries;
                          j["delivery_status"] = st.delivery_status;
                          j["discovery_status"] = st.discovery_status;
                        },
                        [&](const TxRequest& tx) {
                          j["frame_type_name"] = "tx_request";
                          j["frame_id"] = tx.frame_id;
                          j["destination64"] = hex_be(tx.destination64, 8);
                          j["destination16"] = hex_be(tx.destination16, 2);
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
