#include "protocol/mavlink.hpp"

#include <algorithm>
#include <cstring>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <utility>

#include "protocol/crc.hpp"

namespace imubridge::protocol::mavlink {
namespace {

bool is_stx(std::uint8_t byte) { return byte == kStxV1 || byte == kStxV2; }

// A candidate's header fields; the bytes must hold the whole header.
struct Header {
  std::uint8_t version, len, incompat_flags, seq, sysid, compid;
  std::uint32_t msgid;
  std::size_t size;  // header bytes, STX included

  static Header read(const std::uint8_t* p) {
    if (p[0] == kStxV1) return {1, p[1], 0, p[2], p[3], p[4], p[5], kHeaderSizeV1};
    return {2, p[1], p[2], p[4], p[5], p[6], static_cast<std::uint32_t>(p[7] | p[8] << 8 | p[9] << 16), kHeaderSizeV2};
  }
  bool is_signed() const { return incompat_flags & kIncompatSigned; }
  std::size_t frame_size() const { return size + len + kCrcSize + (is_signed() ? kSignatureSize : 0); }
};

enum class Verdict { need_more, frame, truncated, bad_flags, bad_crc, no_stx_after };

struct Judgement {
  Verdict verdict;
  Header header{};
};

// Judges the candidate at p[0] (an STX) from the `avail` bytes there. Each verdict depends on those bytes and on
// `at_end` only, so the chunking of the stream cannot change it.
Judgement judge(const std::uint8_t* p, std::size_t avail, bool at_end) {
  const Verdict short_of_bytes = at_end ? Verdict::truncated : Verdict::need_more;
  if (avail < (p[0] == kStxV1 ? kHeaderSizeV1 : kHeaderSizeV2)) return {short_of_bytes};
  const Header h = Header::read(p);
  if (h.incompat_flags & ~kIncompatSigned) return {Verdict::bad_flags};  // a feature we cannot parse
  const std::size_t size = h.frame_size();
  const std::optional<std::uint8_t> extra = crc_extra(h.msgid);
  if (!extra) {
    // Without a CRC_EXTRA nothing can be checked: trust the length only if the next frame starts right after it.
    if (avail > size) return {is_stx(p[size]) ? Verdict::frame : Verdict::no_stx_after, h};
    return {avail == size && at_end ? Verdict::frame : short_of_bytes, h};
  }
  if (avail < size) return {short_of_bytes};
  const std::size_t crc_at = h.size + h.len;
  const std::uint16_t crc = crc16_mcrf4xx_update(crc16_mcrf4xx_fast({p + 1, crc_at - 1}), *extra);
  return {crc == (p[crc_at] | p[crc_at + 1] << 8) ? Verdict::frame : Verdict::bad_crc, h};
}

// The next byte that may start a frame. memchr looks for one value and MAVLink has two STX values, so each is
// searched for on its own and its hit remembered until passed: every byte is looked at once per value.
class StxFinder {
 public:
  StxFinder(const std::uint8_t* begin, const std::uint8_t* end)
      : end_(end), v1_(find(begin, kStxV1)), v2_(find(begin, kStxV2)) {}

  const std::uint8_t* next(const std::uint8_t* from) {
    if (v1_ < from) v1_ = find(from, kStxV1);
    if (v2_ < from) v2_ = find(from, kStxV2);
    return std::min(v1_, v2_);
  }

 private:
  const std::uint8_t* find(const std::uint8_t* from, std::uint8_t stx) const {
    const void* hit = std::memchr(from, stx, static_cast<std::size_t>(end_ - from));
    return hit ? static_cast<const std::uint8_t*>(hit) : end_;
  }

  const std::uint8_t* end_;
  const std::uint8_t* v1_;
  const std::uint8_t* v2_;
};

// Fills `m` from a frame that passed judge().
const Message& read_message(const std::uint8_t* frame, const Header& h, Message& m) {
  m.version = h.version;
  m.seq = h.seq;
  m.sysid = h.sysid;
  m.compid = h.compid;
  m.msgid = h.msgid;
  m.len = h.len;
  std::copy_n(frame + h.size, h.len, m.payload.begin());
  m.signed_ = h.is_signed();
  return m;
}

std::string hex(std::span<const std::uint8_t> bytes) {
  static constexpr char kDigits[] = "0123456789ABCDEF";
  std::string text;
  text.reserve(2 * bytes.size());
  for (std::uint8_t b : bytes) text += {kDigits[b >> 4], kDigits[b & 0xF]};
  return text;
}

constexpr double kStandardGravity = 9.80665;  // m/s^2 per g: MAVLink's mG are thousandths of it
constexpr double kMicroteslaPerGauss = 100.0;
constexpr std::uint16_t kHighresMagUpdated = 0x1C0;  // HIGHRES_IMU_UPDATED_XMAG | YMAG | ZMAG
constexpr std::uint16_t kHighresTemperatureUpdated = 0x1000;

// Temperatures travel in cdegC with 0 meaning "not measured" (a sensor at 0 degC sends 1).
void set_temperature(Sample& s, std::int16_t cdeg) {
  s.has_temperature = cdeg != 0;
  s.temperature_c = cdeg / 100.0;
}

Sample sample_of(const HighresImu& m) {
  Sample s;
  s.device_time_us = static_cast<std::int64_t>(m.time_usec);
  s.accel = {m.xacc, m.yacc, m.zacc};
  s.gyro = {m.xgyro, m.ygyro, m.zgyro};
  // Only fresh readings count: between magnetometer updates the sender repeats its last value.
  s.has_mag = m.fields_updated & kHighresMagUpdated;
  if (s.has_mag) s.mag = {kMicroteslaPerGauss * m.xmag, kMicroteslaPerGauss * m.ymag, kMicroteslaPerGauss * m.zmag};
  s.has_temperature = m.fields_updated & kHighresTemperatureUpdated;
  if (s.has_temperature) s.temperature_c = m.temperature;
  return s;
}

Sample sample_of(const ScaledImu& m) {
  Sample s;
  s.device_time_us = std::int64_t{m.time_boot_ms} * 1000;
  s.accel = {m.xacc * kStandardGravity / 1000, m.yacc * kStandardGravity / 1000, m.zacc * kStandardGravity / 1000};
  s.gyro = {m.xgyro / 1000.0, m.ygyro / 1000.0, m.zgyro / 1000.0};
  s.mag = {m.xmag * kMicroteslaPerGauss / 1000, m.ymag * kMicroteslaPerGauss / 1000,
           m.zmag * kMicroteslaPerGauss / 1000};
  s.has_mag = true;
  set_temperature(s, m.temperature);
  return s;
}

Sample sample_of(const RawImu& m, const Calibration& calibration) {
  Sample s = calibration.to_sample(
      {{m.xacc, m.yacc, m.zacc}, {m.xgyro, m.ygyro, m.zgyro}, {m.xmag, m.ymag, m.zmag}, m.temperature});
  s.device_time_us = static_cast<std::int64_t>(m.time_usec);
  set_temperature(s, m.temperature);  // already cdegC on the wire, not a count for the calibration to scale
  return s;
}

}  // namespace

Message make_message(std::uint32_t msgid, std::span<const std::uint8_t> payload, const FrameOptions& options) {
  if (options.version != 1 && options.version != 2) throw std::invalid_argument("mavlink: version must be 1 or 2");
  if (payload.size() > 255) throw std::invalid_argument("mavlink: payload over 255 bytes");
  if (msgid > (options.version == 1 ? 0xFFu : 0xFFFFFFu)) throw std::invalid_argument("mavlink: message id too large");
  if (options.version == 1 && options.sign) throw std::invalid_argument("mavlink: MAVLink 1 cannot be signed");
  std::size_t len = payload.size();
  if (options.version == 2 && options.truncate) {
    while (len > 1 && payload[len - 1] == 0) --len;
  }
  Message m;
  m.version = options.version;
  m.seq = options.seq;
  m.sysid = options.sysid;
  m.compid = options.compid;
  m.msgid = msgid;
  m.len = static_cast<std::uint8_t>(len);
  std::copy_n(payload.begin(), len, m.payload.begin());
  m.signed_ = options.sign;
  return m;
}

Message make_message(const Decoded& message, const FrameOptions& options) {
  return make_message(message_id(message), encode_payload(message, options.version == 2), options);
}

void encode(const Message& m, std::vector<std::uint8_t>& out) {
  const std::size_t start = out.size();
  const auto id = [&m](int byte) { return static_cast<std::uint8_t>(m.msgid >> (8 * byte)); };
  if (m.version == 1) {
    out.insert(out.end(), {kStxV1, m.len, m.seq, m.sysid, m.compid, id(0)});
  } else {
    const std::uint8_t incompat_flags = m.signed_ ? kIncompatSigned : 0;
    out.insert(out.end(), {kStxV2, m.len, incompat_flags, 0, m.seq, m.sysid, m.compid, id(0), id(1), id(2)});
  }
  out.insert(out.end(), m.payload.begin(), m.payload.begin() + m.len);
  const std::uint16_t crc =
      crc16_mcrf4xx_update(crc16_mcrf4xx_fast(std::span(out).subspan(start + 1)), crc_extra(m.msgid).value_or(0));
  out.insert(out.end(), {static_cast<std::uint8_t>(crc), static_cast<std::uint8_t>(crc >> 8)});
  if (m.signed_) out.insert(out.end(), kSignatureSize, 0);
}

void Decoder::feed(std::span<const std::uint8_t> chunk, std::vector<Message>& out) {
  counters_.bytes_in += chunk.size();
  if (!pending_.empty()) {
    // kMaxFrameSize + 1 more bytes decide any carried-over candidate (an unknown id looks one byte past its end),
    // so only that much of the chunk is copied; the rest is scanned where it lies.
    const std::size_t carried = pending_.size();
    const std::size_t take = std::min(chunk.size(), kMaxFrameSize + 1);
    pending_.insert(pending_.end(), chunk.begin(), chunk.begin() + static_cast<std::ptrdiff_t>(take));
    const std::size_t used = scan(pending_, false, out);
    if (used < carried) {  // still undecided, which means the whole chunk is now in pending_
      pending_.erase(pending_.begin(), pending_.begin() + static_cast<std::ptrdiff_t>(used));
      return;
    }
    pending_.clear();
    chunk = chunk.subspan(used - carried);
  }
  const std::size_t used = scan(chunk, false, out);
  pending_.assign(chunk.begin() + static_cast<std::ptrdiff_t>(used), chunk.end());
}

void Decoder::finish(std::vector<Message>& out) {
  scan(pending_, true, out);
  pending_.clear();
}

std::size_t Decoder::scan(std::span<const std::uint8_t> data, bool at_end, std::vector<Message>& out) {
  const std::uint8_t* const begin = data.data();
  const std::uint8_t* const end = begin + data.size();
  StxFinder stx(begin, end);
  const std::uint8_t* p = begin;
  while (p < end) {
    const std::uint8_t* candidate = stx.next(p);
    counters_.bytes_discarded += static_cast<std::size_t>(candidate - p);
    p = candidate;
    if (p == end) break;

    const auto [verdict, header] = judge(p, static_cast<std::size_t>(end - p), at_end);
    switch (verdict) {
      case Verdict::need_more:
        return static_cast<std::size_t>(p - begin);
      case Verdict::frame:
        count(read_message(p, header, out.emplace_back()));
        p += header.frame_size();
        break;
      case Verdict::bad_crc:
        ++counters_.crc_failures;
        [[fallthrough]];
      case Verdict::truncated:
      case Verdict::bad_flags:
      case Verdict::no_stx_after:
        // A false start: only its STX is dropped, so a frame that begins inside the rejected bytes is still found.
        ++counters_.resyncs;
        ++counters_.bytes_discarded;
        ++p;
        break;
    }
  }
  return data.size();
}

void Decoder::count(const Message& m) {
  ++counters_.frames_out;
  if (!is_decoded(m.msgid)) ++counters_.unsupported;
  const auto [last, first] = last_seq_.try_emplace(static_cast<std::uint16_t>(m.sysid << 8 | m.compid), m.seq);
  if (first) return;
  // Each sender numbers its frames mod 256, so the frames skipped are the step minus one, mod 256; a repeated number
  // reads as 255 lost, as in MAVLink's own drop counter.
  const auto lost = static_cast<std::uint8_t>(m.seq - last->second - 1);
  if (lost != 0) {
    ++counters_.sequence_gaps;
    counters_.frames_lost += lost;
  }
  last->second = m.seq;
}

void to_json(nlohmann::json& j, const Message& m) {
  j = nlohmann::json{{"protocol", "mavlink"}, {"version", m.version}, {"seq", m.seq}, {"sysid", m.sysid},
                     {"compid", m.compid},    {"msgid", m.msgid},     {"len", m.len}, {"signed", m.signed_}};
  if (const std::optional<Decoded> decoded = decode(m)) {
    std::visit(
        [&j]<typename M>(const M& message) {
          j["name"] = M::kName;
          M::for_each_field(message, [&j](std::string_view name, const auto& value) { j[name] = value; });
        },
        *decoded);
  } else {
    j["payload"] = hex(std::span(m.payload).first(m.len));
  }
}

std::optional<Sample> to_sample(const Message& m, const Calibration* raw_calibration) {
  const std::optional<Decoded> decoded = decode(m);
  if (!decoded) return std::nullopt;
  std::optional<Sample> s;
  if (const auto* highres = std::get_if<HighresImu>(&*decoded)) s = sample_of(*highres);
  if (const auto* scaled = std::get_if<ScaledImu>(&*decoded)) s = sample_of(*scaled);
  if (const auto* raw = std::get_if<RawImu>(&*decoded); raw && raw_calibration) s = sample_of(*raw, *raw_calibration);
  if (s) s->seq = m.seq;
  return s;
}

}  // namespace imubridge::protocol::mavlink
