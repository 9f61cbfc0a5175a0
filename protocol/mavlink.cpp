#include "protocol/mavlink.hpp"

#include <algorithm>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <utility>

#include "protocol/byte_order.hpp"
#include "protocol/crc.hpp"
#include "protocol/hex.hpp"
#include "protocol/units.hpp"

namespace imubridge::protocol::mavlink {
namespace {

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

// What decoding asks of every frame's id: its spec (judge) and its clock and whether it has typed fields (take).
struct IdFacts {
  const MessageSpec* spec = nullptr;
  std::optional<ClockField> clock;
  bool decoded = false;

  static IdFacts of(std::uint32_t msgid) { return {message_spec(msgid), clock_field(msgid), is_decoded(msgid)}; }
};

// For the ids of MAVLink 1's range, where a link's IMU, attitude and position messages are, the facts are gathered
// once: a frame costs one look-up instead of three searches, which took about a tenth of the decoder's instructions.
// Other ids ask each time. Inline, so that a frame's look-up copies only the facts it reads.
inline IdFacts id_facts(std::uint32_t msgid) {
  static const std::array<IdFacts, 256> kLowIds = [] {
    std::array<IdFacts, 256> facts;
    for (std::uint32_t id = 0; id < facts.size(); ++id) facts[id] = IdFacts::of(id);
    return facts;
  }();
  if (msgid < kLowIds.size()) [[likely]]
    return kLowIds[msgid];
  return IdFacts::of(msgid);
}

// Fills `m` from a frame that passed judge().
void read_message(const std::uint8_t* frame, const Header& h, Message& m) {
  m.version = h.version;
  m.seq = h.seq;
  m.sysid = h.sysid;
  m.compid = h.compid;
  m.msgid = h.msgid;
  m.len = h.len;
  std::copy_n(frame + h.size, h.len, m.payload.begin());
  m.signed_ = h.is_signed();
}

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

template <std::uint32_t Id>
Sample sample_of(const ScaledImuOf<Id>& m) {
  Sample s;
  s.device_time_us = std::int64_t{m.time_boot_ms} * 1000;
  // mG are thousandths of standard gravity.
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
  append_le(
      out, crc16_mcrf4xx_update(crc16_mcrf4xx_fast(std::span(out).subspan(start + 1)), crc_extra(m.msgid).value_or(0)));
  if (m.signed_) out.insert(out.end(), kSignatureSize, 0);
}

void Decoder::feed(std::span<const std::uint8_t> chunk, std::vector<Message>& out) { scanner_.feed(chunk, out); }

void Decoder::finish(std::vector<Message>& out) { scanner_.finish(out); }

namespace {

// The checks after the header's, for a candidate `c` that holds its whole header `h` and whose id has `spec`.
FrameCheck check_known(std::span<const std::uint8_t> c, const Header& h, const MessageSpec& spec) {
  using Status = FrameCheck::Status;
  const std::size_t size = h.frame_size();
  // A MAVLink 1 frame carries the base fields, perhaps the extensions, never more. MAVLink 2 lengths are not
  // checked: a newer sender may append extensions the table does not know yet, and its frames verify all the same.
  if (h.version == 1 && (h.len < spec.min_length || h.len > spec.max_length)) return {Status::malformed, size};
  if (c.size() < size) return {Status::cut_short, size};
  const std::size_t crc_at = h.size + h.len;
  const std::uint16_t crc = crc16_mcrf4xx_update(crc16_mcrf4xx_fast(c.subspan(1, crc_at - 1)), spec.crc_extra);
  return {crc == load_le<std::uint16_t>(&c[crc_at]) ? Status::frame : Status::bad_crc, size};
}

}  // namespace

FrameCheck check_frame(std::span<const std::uint8_t> c) {
  using Status = FrameCheck::Status;
  if (c.empty() || (c[0] != kStxV1 && c[0] != kStxV2)) return {Status::malformed};
  if (c.size() < (c[0] == kStxV1 ? kHeaderSizeV1 : kHeaderSizeV2)) return {Status::cut_short};
  const Header h = Header::read(c.data());
  if (h.incompat_flags & ~kIncompatSigned) return {Status::malformed};  // a feature we cannot parse
  const MessageSpec* spec = message_spec(h.msgid);
  const bool whole = c.size() >= h.frame_size();
  if (!spec) return {whole ? Status::unverified : Status::cut_short, h.frame_size(), h.msgid};
  FrameCheck check = check_known(c, h, *spec);
  // The only malformed check_known finds is a MAVLink 1 length: a stream's decoder rejects it at once, but a log,
  // which says where frames start, holds a frame of a layout not known here.
  if (check.status == Status::malformed) check.status = whole ? Status::other_layout : Status::cut_short;
  check.msgid = h.msgid;
  return check;
}

// Each verdict depends on the candidate's bytes only, so the chunking of the stream cannot change it.
inline Judgement Decoder::Framing::judge(std::span<const std::uint8_t> c, bool /*at_end*/) const {
  if (c.size() < (c[0] == kStxV1 ? kHeaderSizeV1 : kHeaderSizeV2)) return {Verdict::need_more};
  const Header h = Header::read(c.data());
  if (h.incompat_flags & ~kIncompatSigned) return {Verdict::false_start};  // a feature we cannot parse
  const MessageSpec* spec = id_facts(h.msgid).spec;
  if (!spec) return {Verdict::unverified};  // without its CRC_EXTRA no CRC can be checked
  const FrameCheck check = check_known(c, h, *spec);
  switch (check.status) {
    case FrameCheck::Status::frame:
      return {Verdict::frame, check.size};
    case FrameCheck::Status::bad_crc:
      return {Verdict::bad_crc, check.size};
    case FrameCheck::Status::cut_short:
      return {Verdict::need_more};
    case FrameCheck::Status::unverified:
    case FrameCheck::Status::other_layout:
    case FrameCheck::Status::malformed:
      break;
  }
  return {Verdict::false_start};
}

inline bool Decoder::Framing::take(std::span<const std::uint8_t> f, std::vector<Message>& out,
                                   DecoderCounters& counters) {
  const Header h = Header::read(f.data());
  Message& m = out.emplace_back();
  read_message(f.data(), h, m);
  const IdFacts facts = id_facts(h.msgid);
  const std::optional<ClockField>& clock = facts.clock;
  const std::optional<std::uint64_t> time = clock ? std::optional(read_clock(m.payload.data(), *clock)) : std::nullopt;
  // Each component numbers its own frames, mod 256.
  const auto id = static_cast<std::uint16_t>(h.sysid << 8 | h.compid);
  if (last_found >= components.size() || components[last_found].id != id) {
    last_found = static_cast<std::size_t>(
        std::find_if(components.begin(), components.end(), [id](const Component& c) { return c.id == id; }) -
        components.begin());
  }
  if (last_found == components.size()) {
    components.push_back({.id = id, .last_seq = h.seq});
  } else {
    Component& c = components[last_found];
    if (time && c.has_time[clock->slot] && is_restart(c.last_seq, h.seq, c.last_time_us[clock->slot], *time)) {
      // Its numbers start again: the step to them is no loss.
      ++counters.device_restarts;
      ++clock_epoch;
      c.has_time.fill(false);
    } else if (count_sequence_step(c.last_seq, h.seq, counters) == 0) {
      out.pop_back();  // sent again
      return false;
    }
    c.last_seq = h.seq;
  }
  if (time) {
    components[last_found].last_time_us[clock->slot] = *time;
    components[last_found].has_time[clock->slot] = true;
  }
  if (!facts.decoded) ++counters.unsupported;
  m.clock_epoch = clock_epoch;
  return true;
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
  if (const auto* scaled = std::get_if<ScaledImu2>(&*decoded)) s = sample_of(*scaled);
  if (const auto* scaled = std::get_if<ScaledImu3>(&*decoded)) s = sample_of(*scaled);
  if (const auto* raw = std::get_if<RawImu>(&*decoded); raw && raw_calibration) s = sample_of(*raw, *raw_calibration);
  if (s) {
    s->seq = m.seq;
    s->clock_epoch = m.clock_epoch;
  }
  return s;
}

std::optional<ImuSource> imu_source(const Message& m) {
  const std::optional<Decoded> decoded = decode(m);
  if (!decoded) return std::nullopt;
  ImuSource source{.msgid = m.msgid, .sysid = m.sysid, .compid = m.compid};
  if (const auto* highres = std::get_if<HighresImu>(&*decoded)) {
    source.id = highres->id;
  } else if (const auto* raw = std::get_if<RawImu>(&*decoded)) {
    source.id = raw->id;
  } else if (!std::holds_alternative<ScaledImu>(*decoded) && !std::holds_alternative<ScaledImu2>(*decoded) &&
             !std::holds_alternative<ScaledImu3>(*decoded)) {
    return std::nullopt;
  }
  return source;
}

std::string describe(const ImuSource& source) {
  const MessageSpec* spec = message_spec(source.msgid);
  std::string text = spec ? std::string(spec->name) : "message " + std::to_string(source.msgid);
  if (source.msgid == HighresImu::kId || source.msgid == RawImu::kId) text += " id " + std::to_string(source.id);
  return text + " from system " + std::to_string(source.sysid) + ", component " + std::to_string(source.compid);
}

}  // namespace imubridge::protocol::mavlink
