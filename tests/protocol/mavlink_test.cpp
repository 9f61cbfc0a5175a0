#include "protocol/mavlink.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <random>
#include <stdexcept>
#include <string>
#include <string_view>
#include <tuple>
#include <vector>

#include "protocol/crc.hpp"
#include "tests/support/decoder_harness.hpp"

namespace imubridge::protocol::mavlink {
namespace {

using Bytes = std::vector<std::uint8_t>;

using harness::append;
using harness::crc_bit_serial;

Bytes bytes_of(const Message& m) {
  Bytes out;
  encode(m, out);
  return out;
}

Bytes bytes_of(const Decoded& message, const FrameOptions& options) { return bytes_of(make_message(message, options)); }

using Decoding = harness::Decoded<Decoder>;

// Feeds `stream` in pieces of `chunk` bytes (0: all at once), then finishes.
Decoding decode_stream(std::span<const std::uint8_t> stream, std::size_t chunk = 0) {
  return harness::decode_chunked(Decoder{}, stream, chunk);
}

std::uint64_t frame_bytes(const std::vector<Message>& messages) {
  std::uint64_t n = 0;
  for (const Message& m : messages) n += bytes_of(m).size();
  return n;
}

// Tests that count false starts exactly damage frames whose only STX is their first byte: another one inside would
// be one more candidate to reject.
bool stx_only_in_front(const Bytes& frame) {
  return std::none_of(frame.begin() + 1, frame.end(), [](std::uint8_t b) { return b == kStxV1 || b == kStxV2; });
}

constexpr std::uint32_t kUnknownId = 0xABCDE;  // in none of the dialects protocol/mavlink_message_specs.cpp holds

// A MAVLink 1 id (8 bits) in none of those dialects.
std::uint32_t unknown_v1_id() {
  for (std::uint32_t id = 0; id < 256; ++id) {
    if (!message_spec(id)) return id;
  }
  throw std::logic_error("every MAVLink 1 id is known");
}

// ---- The messages, as common.xml (and minimal.xml for HEARTBEAT) define them ----

// Fields in definition order, with the types as the XML writes them; extensions apart.
struct FieldDef {
  std::string_view type, name;
};
struct MessageDef {
  std::string_view name;
  std::uint32_t id;
  std::vector<FieldDef> fields, extensions;
};

const MessageDef kHighresImuDef{"HIGHRES_IMU",
                                105,
                                {{"uint64_t", "time_usec"},
                                 {"float", "xacc"},
                                 {"float", "yacc"},
                                 {"float", "zacc"},
                                 {"float", "xgyro"},
                                 {"float", "ygyro"},
                                 {"float", "zgyro"},
                                 {"float", "xmag"},
                                 {"float", "ymag"},
                                 {"float", "zmag"},
                                 {"float", "abs_pressure"},
                                 {"float", "diff_pressure"},
                                 {"float", "pressure_alt"},
                                 {"float", "temperature"},
                                 {"uint16_t", "fields_updated"}},
                                {{"uint8_t", "id"}}};
const MessageDef kScaledImuDef{"SCALED_IMU",
                               26,
                               {{"uint32_t", "time_boot_ms"},
                                {"int16_t", "xacc"},
                                {"int16_t", "yacc"},
                                {"int16_t", "zacc"},
                                {"int16_t", "xgyro"},
                                {"int16_t", "ygyro"},
                                {"int16_t", "zgyro"},
                                {"int16_t", "xmag"},
                                {"int16_t", "ymag"},
                                {"int16_t", "zmag"}},
                               {{"int16_t", "temperature"}}};
const MessageDef kRawImuDef{"RAW_IMU",
                            27,
                            {{"uint64_t", "time_usec"},
                             {"int16_t", "xacc"},
                             {"int16_t", "yacc"},
                             {"int16_t", "zacc"},
                             {"int16_t", "xgyro"},
                             {"int16_t", "ygyro"},
                             {"int16_t", "zgyro"},
                             {"int16_t", "xmag"},
                             {"int16_t", "ymag"},
                             {"int16_t", "zmag"}},
                            {{"uint8_t", "id"}, {"int16_t", "temperature"}}};
const MessageDef kAttitudeDef{"ATTITUDE",
                              30,
                              {{"uint32_t", "time_boot_ms"},
                               {"float", "roll"},
                               {"float", "pitch"},
                               {"float", "yaw"},
                               {"float", "rollspeed"},
                               {"float", "pitchspeed"},
                               {"float", "yawspeed"}},
                              {}};
// SCALED_IMU2 and SCALED_IMU3 are SCALED_IMU's fields under other names, so other CRC_EXTRAs.
MessageDef renamed(const MessageDef& def, std::string_view name, std::uint32_t id) {
  MessageDef copy = def;
  copy.name = name;
  copy.id = id;
  return copy;
}
const MessageDef kScaledImu2Def = renamed(kScaledImuDef, "SCALED_IMU2", 116);
const MessageDef kScaledImu3Def = renamed(kScaledImuDef, "SCALED_IMU3", 129);
const MessageDef kAttitudeQuaternionDef{"ATTITUDE_QUATERNION",
                                        31,
                                        {{"uint32_t", "time_boot_ms"},
                                         {"float", "q1"},
                                         {"float", "q2"},
                                         {"float", "q3"},
                                         {"float", "q4"},
                                         {"float", "rollspeed"},
                                         {"float", "pitchspeed"},
                                         {"float", "yawspeed"}},
                                        {{"float[4]", "repr_offset_q"}}};
const MessageDef kLocalPositionNedDef{"LOCAL_POSITION_NED",
                                      32,
                                      {{"uint32_t", "time_boot_ms"},
                                       {"float", "x"},
                                       {"float", "y"},
                                       {"float", "z"},
                                       {"float", "vx"},
                                       {"float", "vy"},
                                       {"float", "vz"}},
                                      {}};
// Two that exercise the rest of the rules: a field to re-order, MAVLink's own version type, and an array.
const MessageDef kHeartbeatDef{"HEARTBEAT",
                               0,
                               {{"uint8_t", "type"},
                                {"uint8_t", "autopilot"},
                                {"uint8_t", "base_mode"},
                                {"uint32_t", "custom_mode"},
                                {"uint8_t", "system_status"},
                                {"uint8_t_mavlink_version", "mavlink_version"}},
                               {}};
const MessageDef kParamValueDef{"PARAM_VALUE",
                                22,
                                {{"char[16]", "param_id"},
                                 {"float", "param_value"},
                                 {"uint8_t", "param_type"},
                                 {"uint16_t", "param_count"},
                                 {"uint16_t", "param_index"}},
                                {}};

struct WireField {
  std::string type;  // element type, as it enters CRC_EXTRA
  std::string_view name;
  std::size_t array_length = 0;  // 0: not an array
  std::size_t element_size = 0;
  std::size_t offset = 0;
};

std::size_t type_size(std::string_view type) {
  if (type == "uint8_t" || type == "int8_t" || type == "char") return 1;
  if (type == "uint16_t" || type == "int16_t") return 2;
  if (type == "uint32_t" || type == "int32_t" || type == "float") return 4;
  if (type == "uint64_t" || type == "int64_t" || type == "double") return 8;
  throw std::invalid_argument("unknown type " + std::string(type));
}

WireField wire_field(const FieldDef& def) {
  WireField f;
  f.type = def.type;
  f.name = def.name;
  if (const auto bracket = f.type.find('['); bracket != std::string::npos) {
    f.array_length = std::stoul(f.type.substr(bracket + 1));
    f.type.resize(bracket);
  }
  if (f.type == "uint8_t_mavlink_version") f.type = "uint8_t";
  f.element_size = type_size(f.type);
  return f;
}

// MAVLink's wire order: base fields sorted by element size, largest first, keeping definition order among equals;
// extensions after them in definition order.
std::vector<WireField> wire_order(const MessageDef& def) {
  std::vector<WireField> fields;
  for (const FieldDef& f : def.fields) fields.push_back(wire_field(f));
  std::ranges::stable_sort(fields, std::greater<>{}, &WireField::element_size);
  for (const FieldDef& f : def.extensions) fields.push_back(wire_field(f));
  std::size_t offset = 0;
  for (WireField& f : fields) {
    f.offset = offset;
    offset += f.element_size * std::max<std::size_t>(f.array_length, 1);
  }
  return fields;
}

// CRC_EXTRA as MAVLink's generator computes it: the CRC of the message name and of each base field's type and name
// (each followed by a space) and array length, folded to one byte.
std::uint8_t crc_extra_from_definition(const MessageDef& def) {
  auto add = [](std::uint16_t crc, std::string_view text) {
    for (char c : text) crc = crc16_mcrf4xx_update(crc, static_cast<std::uint8_t>(c));
    return crc16_mcrf4xx_update(crc, ' ');
  };
  std::uint16_t crc = add(kCrc16Init, def.name);
  const std::vector<WireField> fields = wire_order(def);
  for (std::size_t i = 0; i < def.fields.size(); ++i) {
    crc = add(add(crc, fields[i].type), fields[i].name);
    if (fields[i].array_length) crc = crc16_mcrf4xx_update(crc, static_cast<std::uint8_t>(fields[i].array_length));
  }
  return static_cast<std::uint8_t>((crc & 0xFF) ^ (crc >> 8));
}

std::size_t payload_length(const std::vector<WireField>& fields, std::size_t count) {
  return count == 0 ? 0
                    : fields[count - 1].offset +
                          fields[count - 1].element_size * std::max<std::size_t>(fields[count - 1].array_length, 1);
}

// A field read straight from payload bytes, as JSON (an array as an array), to compare with what to_json made of it.
nlohmann::json read_field(const WireField& f, const std::uint8_t* p) {
  if (f.array_length) {
    WireField element = f;
    element.array_length = 0;
    nlohmann::json elements = nlohmann::json::array();
    for (std::size_t i = 0; i < f.array_length; ++i) elements.push_back(read_field(element, p + i * f.element_size));
    return elements;
  }
  std::uint64_t bits = 0;
  for (std::size_t i = 0; i < f.element_size; ++i) bits |= std::uint64_t{p[i]} << (8 * i);
  if (f.type == "float") return std::bit_cast<float>(static_cast<std::uint32_t>(bits));
  if (f.type == "int16_t") return static_cast<std::int16_t>(bits);
  return bits;  // the unsigned types
}

TEST(MavlinkCrc, PublishedCheckValue) {
  const std::string_view text = "123456789";
  const std::span<const std::uint8_t> check(reinterpret_cast<const std::uint8_t*>(text.data()), text.size());
  EXPECT_EQ(crc_bit_serial(check), 0x6F91);
  EXPECT_EQ(crc16_mcrf4xx(check), 0x6F91);
  EXPECT_EQ(crc16_mcrf4xx_fast(check), 0x6F91);  // what the decoder uses
}

TEST(MavlinkDefinitions, CrcExtraComputedFromTheDefinitions) {
  for (const MessageDef* def :
       {&kHighresImuDef, &kScaledImuDef, &kScaledImu2Def, &kScaledImu3Def, &kRawImuDef, &kAttitudeDef,
        &kAttitudeQuaternionDef, &kLocalPositionNedDef, &kHeartbeatDef, &kParamValueDef}) {
    EXPECT_EQ(crc_extra(def->id), crc_extra_from_definition(*def)) << def->name;
  }
  EXPECT_EQ(crc_extra(0xABCDE), std::nullopt);
}

// What MAVLink's own generator wrote into its C headers (MAVLINK_MSG_ID_<name>_CRC, _MIN_LEN and _LEN), from each
// dialect file the table is made of.
TEST(MavlinkDefinitions, TableAgreesWithMavlinksGeneratedHeaders) {
  struct Published {
    std::uint32_t id;
    std::string_view name;
    int crc_extra, min_length, max_length;
  };
  const Published published[] = {
      {0, "HEARTBEAT", 50, 9, 9},                     // minimal.xml
      {1, "SYS_STATUS", 124, 31, 43},                 // common.xml
      {24, "GPS_RAW_INT", 24, 30, 52},                // common.xml
      {26, "SCALED_IMU", 170, 22, 24},                // common.xml
      {116, "SCALED_IMU2", 76, 22, 24},               // common.xml
      {129, "SCALED_IMU3", 46, 22, 24},               // common.xml
      {31, "ATTITUDE_QUATERNION", 246, 32, 48},       // common.xml
      {32, "LOCAL_POSITION_NED", 185, 28, 28},        // common.xml
      {27, "RAW_IMU", 144, 26, 29},                   // common.xml
      {30, "ATTITUDE", 39, 28, 28},                   // common.xml
      {105, "HIGHRES_IMU", 93, 62, 63},               // common.xml
      {152, "MEMINFO", 208, 4, 8},                    // ardupilotmega.xml
      {163, "AHRS", 127, 28, 28},                     // ardupilotmega.xml
      {355, "VELOCITY_LIMITS", 6, 12, 12},            // development.xml
      {10001, "UAVIONIX_ADSB_OUT_CFG", 209, 20, 20},  // uAvionix.xml
      {42000, "ICAROUS_HEARTBEAT", 227, 1, 1},        // icarous.xml
      {50001, "CUBEPILOT_RAW_RC", 246, 32, 32},       // cubepilot.xml
      {10151, "LOWEHEISER_GOV_EFI", 195, 85, 85},     // loweheiser.xml
      {52000, "AIRLINK_AUTH", 13, 100, 100},          // csAirLink.xml (two char[50])
  };
  for (const Published& p : published) {
    const MessageSpec* spec = message_spec(p.id);
    ASSERT_NE(spec, nullptr) << p.name;
    EXPECT_EQ(spec->name, p.name);
    EXPECT_EQ(spec->crc_extra, p.crc_extra) << p.name;
    EXPECT_EQ(spec->min_length, p.min_length) << p.name;
    EXPECT_EQ(spec->max_length, p.max_length) << p.name;
    EXPECT_EQ(crc_extra(p.id), spec->crc_extra);
  }
  EXPECT_EQ(message_spec(kUnknownId), nullptr);
}

template <typename M>
void expect_layout_matches(const MessageDef& def) {
  SCOPED_TRACE(def.name);
  const std::vector<WireField> fields = wire_order(def);
  EXPECT_EQ(M::kId, def.id);
  EXPECT_EQ(M::kName, def.name);
  EXPECT_EQ(M::kBaseLength, payload_length(fields, def.fields.size()));
  EXPECT_EQ(M::kLength, payload_length(fields, fields.size()));
  ASSERT_NE(message_spec(M::kId), nullptr);
  EXPECT_EQ(message_spec(M::kId)->min_length, M::kBaseLength);
  EXPECT_EQ(message_spec(M::kId)->max_length, M::kLength);

  // Every field a different value, with every byte of it significant.
  M sent;
  std::uint64_t k = 0;
  const auto distinct = [&k]<typename T>(T& scalar) {
    ++k;
    if constexpr (std::is_floating_point_v<T>) {
      scalar = static_cast<T>(k) + 0.375f;
    } else {
      scalar = static_cast<T>(0xF0E0D0C0B0A09080ull + k);
    }
  };
  M::for_each_field(sent, [&](std::string_view, auto& field) {
    if constexpr (requires { field.size(); }) {
      for (auto& element : field) distinct(element);
    } else {
      distinct(field);
    }
  });
  const Message m = make_message(sent, {.truncate = false});
  ASSERT_EQ(m.len, M::kLength);
  const nlohmann::json j = m;
  EXPECT_EQ(j["name"], def.name);
  for (const WireField& f : fields) EXPECT_EQ(read_field(f, &m.payload[f.offset]), j[f.name]) << f.name;
  EXPECT_EQ(std::get<M>(decode(m).value()), sent);
}

TEST(MavlinkDefinitions, WireLayoutMatchesTheDefinitions) {
  expect_layout_matches<HighresImu>(kHighresImuDef);
  expect_layout_matches<ScaledImu>(kScaledImuDef);
  expect_layout_matches<ScaledImu2>(kScaledImu2Def);
  expect_layout_matches<ScaledImu3>(kScaledImu3Def);
  expect_layout_matches<RawImu>(kRawImuDef);
  expect_layout_matches<Attitude>(kAttitudeDef);
  expect_layout_matches<AttitudeQuaternion>(kAttitudeQuaternionDef);
  expect_layout_matches<LocalPositionNed>(kLocalPositionNedDef);
}

// ---- Framing ----

// The example of docs/protocol.md, section "MAVLink": SCALED_IMU in MAVLink 2, written byte by byte from the layout.
const Bytes kDocExample = {
    0xFD,                                // STX: MAVLink 2
    0x18, 0x00, 0x00,                    // len 24, incompat flags, compat flags
    0x07, 0x01, 0x01,                    // seq 7, sysid 1, compid 1
    0x1A, 0x00, 0x00,                    // msgid 26 (SCALED_IMU), 24-bit little-endian
    0x40, 0xE2, 0x01, 0x00,              // time_boot_ms 123456
    0x0C, 0x00, 0xE7, 0xFF, 0x15, 0xFC,  // acc 12, -25, -1003 mG
    0x05, 0x00, 0xF9, 0xFF, 0x2C, 0x01,  // gyro 5, -7, 300 mrad/s
    0xD2, 0x00, 0xA1, 0xFF, 0x20, 0xFE,  // mag 210, -95, -480 mgauss
    0x35, 0x0C,                          // temperature 3125 cdegC (extension)
    0x68, 0x9B,                          // CRC 0x9B68
};
const ScaledImu kDocScaledImu{123456, 12, -25, -1003, 5, -7, 300, 210, -95, -480, 3125};

TEST(MavlinkFrame, DocumentedExample) {
  Bytes covered(kDocExample.begin() + 1, kDocExample.end() - 2);  // after the STX through the payload
  covered.push_back(170);                                         // SCALED_IMU's CRC_EXTRA
  EXPECT_EQ(crc_bit_serial(covered), 0x9B68);

  EXPECT_EQ(bytes_of(kDocScaledImu, {.seq = 7}), kDocExample);
  const Decoding r = decode_stream(kDocExample);
  ASSERT_EQ(r.frames.size(), 1u);
  const Message& m = r.frames[0];
  EXPECT_EQ(m.version, 2);
  EXPECT_EQ(m.seq, 7);
  EXPECT_EQ(m.sysid, 1);
  EXPECT_EQ(m.compid, 1);
  EXPECT_EQ(m.msgid, 26u);
  EXPECT_EQ(m.len, 24);
  EXPECT_FALSE(m.signed_);
  EXPECT_EQ(std::get<ScaledImu>(decode(m).value()), kDocScaledImu);
}

const HighresImu kHighres{.time_usec = 1'700'000'123'456,
                          .xacc = 0.125f,
                          .yacc = -0.5f,
                          .zacc = -9.80665f,
                          .xgyro = 0.01f,
                          .ygyro = -0.02f,
                          .zgyro = 0.5f,
                          .xmag = 0.25f,
                          .ymag = -0.0625f,
                          .zmag = 0.5f,
                          .abs_pressure = 1013.25f,
                          .diff_pressure = 0.5f,
                          .pressure_alt = 120.5f,
                          .temperature = 31.5f,
                          .fields_updated = 0x1FFF,
                          .id = 1};
const ScaledImu kScaled{.time_boot_ms = 4000000,
                        .xacc = 12,
                        .yacc = -25,
                        .zacc = -1003,
                        .xgyro = 5,
                        .ygyro = -7,
                        .zgyro = 300,
                        .xmag = 210,
                        .ymag = -95,
                        .zmag = -180,
                        .temperature = 3125};
const RawImu kRaw{.time_usec = 987654321,
                  .xacc = 2050,
                  .yacc = 2043,
                  .zacc = 1527,
                  .xgyro = -12,
                  .ygyro = 5,
                  .zgyro = 300,
                  .xmag = 210,
                  .ymag = -95,
                  .zmag = -180,
                  .id = 2,
                  .temperature = -1550};
const Attitude kAttitude{.time_boot_ms = 4000010,
                         .roll = 0.1f,
                         .pitch = -0.2f,
                         .yaw = 3.0f,
                         .rollspeed = 0.01f,
                         .pitchspeed = -0.02f,
                         .yawspeed = 0.03f};

TEST(MavlinkFrame, RoundTripsEveryMessageInEveryFraming) {
  // What MAVLink 1 carries: the base fields; the extensions read back as zero.
  HighresImu highres_base = kHighres;
  highres_base.id = 0;
  ScaledImu scaled_base = kScaled;
  scaled_base.temperature = 0;
  RawImu raw_base = kRaw;
  raw_base.id = 0;
  raw_base.temperature = 0;
  // For truncation: values whose last payload bytes are zero, and the length MAVLink 2 sends them with.
  Attitude attitude_still = kAttitude;
  attitude_still.pitchspeed = attitude_still.yawspeed = 0;

  struct Case {
    Decoded sent;
    FrameOptions options;
    Decoded received;
    std::size_t len;
  };
  const std::vector<Case> cases = {
      {kHighres, {.version = 1}, highres_base, 62},
      {kHighres, {.version = 2}, kHighres, 63},
      {highres_base, {.version = 2}, highres_base, 62},  // the zero id is truncated
      {highres_base, {.version = 2, .truncate = false}, highres_base, 63},
      {kHighres, {.version = 2, .sign = true}, kHighres, 63},
      {kScaled, {.version = 1}, scaled_base, 22},
      {kScaled, {.version = 2}, kScaled, 24},
      {scaled_base, {.version = 2}, scaled_base, 22},
      {kScaled, {.version = 2, .sign = true}, kScaled, 24},
      {kRaw, {.version = 1}, raw_base, 26},
      {kRaw, {.version = 2}, kRaw, 29},
      {raw_base, {.version = 2}, raw_base, 26},
      {kRaw, {.version = 2, .sign = true}, kRaw, 29},
      {kAttitude, {.version = 1}, kAttitude, 28},
      {kAttitude, {.version = 2}, kAttitude, 28},
      {attitude_still, {.version = 2}, attitude_still, 20},
      {kAttitude, {.version = 2, .sign = true}, kAttitude, 28},
  };
  for (std::size_t i = 0; i < cases.size(); ++i) {
    const Case& c = cases[i];
    SCOPED_TRACE("case " + std::to_string(i));
    FrameOptions options = c.options;
    options.seq = 200;
    options.sysid = 42;
    options.compid = 7;
    const Bytes bytes = bytes_of(c.sent, options);
    const std::size_t header = c.options.version == 1 ? 6 : 10;
    EXPECT_EQ(bytes.size(), header + c.len + 2 + (c.options.sign ? 13 : 0));

    const Decoding r = decode_stream(bytes);
    ASSERT_EQ(r.frames.size(), 1u);
    const Message& m = r.frames[0];
    EXPECT_EQ(m, make_message(c.sent, options));
    EXPECT_EQ(m.version, c.options.version);
    EXPECT_EQ(m.len, c.len);
    EXPECT_EQ(m.signed_, c.options.sign);
    EXPECT_EQ(std::tie(m.seq, m.sysid, m.compid), std::make_tuple(200, 42, 7));
    EXPECT_EQ(m.msgid, message_id(c.sent));
    EXPECT_EQ(decode(m), c.received);
    EXPECT_EQ(r.counters.bytes_discarded, 0u);
    EXPECT_EQ(r.counters.unsupported, 0u);
  }
}

TEST(MavlinkFrame, SignatureIsSkippedWhateverItHolds) {
  Bytes signed_frame = bytes_of(kAttitude, {.sign = true});
  std::fill(signed_frame.end() - 13, signed_frame.end(), kStxV2);  // outside the CRC: any bytes must do
  Bytes stream = signed_frame;
  append(stream, bytes_of(kScaled, {.seq = 1}));
  const Decoding r = decode_stream(stream);
  ASSERT_EQ(r.frames.size(), 2u);
  EXPECT_TRUE(r.frames[0].signed_);
  EXPECT_EQ(decode(r.frames[1]), Decoded{kScaled});
  EXPECT_EQ(r.counters.resyncs, 0u);
  EXPECT_EQ(r.counters.bytes_discarded, 0u);
}

TEST(MavlinkFrame, EncoderRejectsWhatTheWireCannotCarry) {
  const Bytes payload(10, 1);
  EXPECT_THROW(make_message(300, payload, {.version = 1}), std::invalid_argument);
  EXPECT_THROW(make_message(0x1000000, payload, {.version = 2}), std::invalid_argument);
  EXPECT_THROW(make_message(0, Bytes(256, 1), {}), std::invalid_argument);
  EXPECT_THROW(make_message(0, payload, {.version = 1, .sign = true}), std::invalid_argument);
  EXPECT_THROW(make_message(0, payload, {.version = 3}), std::invalid_argument);
  EXPECT_EQ(make_message(0, Bytes(9, 0), {}).len, 1);  // MAVLink 2 keeps one byte of an all-zero payload
}

// ---- Decoder ----

// A HEARTBEAT: known, CRC-checked, but not decoded.
Bytes heartbeat(std::uint8_t seq) {
  const Bytes payload = {0x04, 0, 0, 0, 2, 12, 0x81, 4, 3};  // custom mode 4, quadrotor, PX4, armed, active, v3
  return bytes_of(make_message(0, payload, {.seq = seq}));
}

// A stream with every kind of trouble, each kind once or twice.
Bytes troubled_stream() {
  Bytes s = {0x00, 0x11, kStxV1, 0x22, kStxV2};  // noise with stray STX bytes
  append(s, bytes_of(kHighres, {.seq = 0}));
  Bytes flipped = bytes_of(kScaled, {.seq = 1});
  flipped[20] ^= 0x04;
  append(s, flipped);
  append(s, {kStxV1, 30, 0, 1, 1, 30});  // an ATTITUDE header over 30 bytes; real frames begin inside it
  append(s, bytes_of(kAttitude, {.version = 1, .seq = 2}));
  append(s, heartbeat(3));
  append(s, {kStxV2, 0xFF, 0, 0, 4, 1, 1, 27, 0, 0});  // a RAW_IMU header claiming 255 bytes, over six real frames
  for (std::uint8_t seq = 4; seq < 10; ++seq) append(s, bytes_of(kRaw, {.seq = seq}));
  append(s, {kStxV2, 4, 0x02, 0, 10, 1, 1, 30, 0, 0});                         // an incompat flag we cannot parse
  append(s, bytes_of(make_message(kUnknownId, Bytes{1, 2, 3}, {.seq = 11})));  // unverifiable, though an STX follows
  append(s, bytes_of(kHighres, {.seq = 12, .sign = true}));
  const Bytes last = bytes_of(kScaled, {.seq = 13});
  s.insert(s.end(), last.begin(), last.begin() + 20);  // cut off by the end of the stream
  return s;
}

TEST(MavlinkDecoder, SameMessagesAndCountersAtEverySplitPoint) {
  const Bytes stream = troubled_stream();
  const Decoding whole = decode_stream(stream);
  ASSERT_EQ(whole.frames.size(), 10u);  // seq 0, 2..9, 12
  EXPECT_EQ(whole.counters.bytes_in, whole.counters.bytes_discarded + frame_bytes(whole.frames));

  EXPECT_EQ(harness::first_split_that_differs(Decoder{}, stream, whole), std::nullopt);
}

TEST(MavlinkDecoder, SameMessagesAndCountersForAnyChunkSize) {
  Bytes stream;
  for (int i = 0; i < 10; ++i) append(stream, troubled_stream());
  const Decoding whole = decode_stream(stream);
  for (std::size_t chunk : {1u, 2u, 3u, 35u, 36u, 37u, 280u, 281u, 282u, 4096u}) {
    const Decoding r = decode_stream(stream, chunk);
    EXPECT_EQ(r.frames, whole.frames) << "chunk " << chunk;
    EXPECT_EQ(r.counters, whole.counters) << "chunk " << chunk;
  }
}

TEST(MavlinkDecoder, GarbageTruncationAndBitFlipsCountedExactly) {
  const Bytes noise = {0x00, 0x55, 0xAA, 0x13};
  const Bytes a = bytes_of(kHighres, {.seq = 0});
  Bytes b = bytes_of(kScaled, {.seq = 1});
  const Bytes c = bytes_of(kAttitude, {.version = 1, .seq = 2});
  const Bytes d = bytes_of(kRaw, {.seq = 3});
  const Bytes e = bytes_of(kScaled, {.seq = 4});
  b[15] ^= 0x01;  // a bit flip in the payload
  ASSERT_TRUE(stx_only_in_front(b));
  ASSERT_TRUE(stx_only_in_front(d));

  Bytes stream = noise;
  append(stream, a);
  append(stream, b);
  append(stream, c);
  stream.insert(stream.end(), d.begin(), d.begin() + 17);  // d cut short: its CRC is checked over e's bytes
  append(stream, e);
  stream.push_back(0x77);  // trailing noise

  const Decoding r = decode_stream(stream);
  ASSERT_EQ(r.frames.size(), 3u);
  EXPECT_EQ(r.frames[0], make_message(kHighres, {.seq = 0}));
  EXPECT_EQ(r.frames[1], make_message(kAttitude, {.version = 1, .seq = 2}));
  EXPECT_EQ(r.frames[2], make_message(kScaled, {.seq = 4}));

  DecoderCounters expected;
  expected.bytes_in = stream.size();
  expected.frames_out = 3;
  expected.crc_failures = 2;  // b and d
  expected.resyncs = 2;
  expected.bytes_discarded = noise.size() + b.size() + 17 + 1;
  expected.sequence_gaps = 2;  // 0 -> 2 and 2 -> 4
  expected.frames_lost = 2;
  EXPECT_EQ(r.counters, expected);
}

TEST(MavlinkDecoder, FindsFrameStartingInsideRejectedCandidate) {
  // A false STX whose header claims a known id and a length that covers the next frame and runs into the one after.
  // A parser that drops a rejected candidate's claimed length (the MAVLink C library, mavlink-router) loses both.
  const Bytes inner = bytes_of(kHighres, {.seq = 5});
  const Bytes next = bytes_of(kAttitude, {.seq = 6});
  const Bytes false_start = {kStxV2, static_cast<std::uint8_t>(inner.size() + 10), 0, 0, 9, 1, 1, HighresImu::kId, 0,
                             0};
  Bytes stream = false_start;
  append(stream, inner);
  append(stream, next);

  const Decoding r = decode_stream(stream);
  ASSERT_EQ(r.frames.size(), 2u);
  EXPECT_EQ(decode(r.frames[0]), Decoded{kHighres});
  EXPECT_EQ(decode(r.frames[1]), Decoded{kAttitude});
  EXPECT_EQ(r.counters.crc_failures, 1u);
  EXPECT_EQ(r.counters.resyncs, 1u);
  EXPECT_EQ(r.counters.bytes_discarded, false_start.size());
}

TEST(MavlinkDecoder, UnknownIdsAreUnverifiedNotFrames) {
  const Bytes unknown_frame = bytes_of(make_message(kUnknownId, Bytes{9, 8, 7}, {.seq = 0}));
  ASSERT_TRUE(stx_only_in_front(unknown_frame));
  const Bytes good_heartbeat = heartbeat(1);
  Bytes stream = unknown_frame;    // followed by an STX
  append(stream, good_heartbeat);  // known id, not decoded: CRC-checked, counted unsupported
  append(stream, unknown_frame);   // followed by a non-STX byte
  stream.push_back(0x42);
  Bytes bad_heartbeat = heartbeat(2);
  bad_heartbeat[12] ^= 0x80;  // a known id's CRC is checked even though it is not decoded
  ASSERT_TRUE(stx_only_in_front(bad_heartbeat));
  append(stream, bad_heartbeat);
  append(stream, unknown_frame);  // ends the stream

  const Decoding r = decode_stream(stream);
  ASSERT_EQ(r.frames.size(), 1u);
  EXPECT_EQ(r.frames[0].msgid, 0u);
  EXPECT_EQ(nlohmann::json(r.frames[0])["payload"], "04000000020C810403");  // undecoded: payload bytes in hex
  EXPECT_EQ(r.counters, (DecoderCounters{.bytes_in = stream.size(),
                                         .frames_out = 1,
                                         .crc_failures = 1,
                                         .resyncs = 1,
                                         .bytes_discarded = stream.size() - good_heartbeat.size(),
                                         .unsupported = 1,
                                         .unverified = 3}));

  // The header decides: nothing waits for the rest of an unverifiable candidate or for the byte after it.
  Decoder decoder;
  std::vector<Message> out;
  decoder.feed(std::span(unknown_frame).first(kHeaderSizeV2), out);
  EXPECT_TRUE(out.empty());
  EXPECT_EQ(decoder.counters().unverified, 1u);
}

TEST(MavlinkDecoder, FrameStartingInsideAnUnverifiableCandidateIsFound) {
  // A frame with an id outside the dialects carries real frames in its payload and is followed by another: trusting
  // the unverifiable length would lose the two inside.
  for (const std::uint8_t version : {1, 2}) {
    SCOPED_TRACE("MAVLink " + std::to_string(version));
    const Message inner_v2 = make_message(kAttitude, {.seq = 1});
    const Message inner_v1 = make_message(kScaled, {.version = 1, .seq = 2});
    Bytes payload = bytes_of(inner_v2);
    append(payload, bytes_of(inner_v1));
    const std::uint32_t id = version == 1 ? unknown_v1_id() : kUnknownId;
    const Bytes wrapper = bytes_of(make_message(id, payload, {.version = version, .seq = 0}));
    const Message after = make_message(kHighres, {.version = version, .seq = 3});
    Bytes stream = wrapper;
    append(stream, bytes_of(after));
    const std::size_t header = version == 1 ? kHeaderSizeV1 : kHeaderSizeV2;
    ASSERT_TRUE(std::none_of(wrapper.begin() + 1, wrapper.begin() + header,
                             [](std::uint8_t b) { return b == kStxV1 || b == kStxV2; }));
    ASSERT_TRUE(
        std::none_of(wrapper.end() - 2, wrapper.end(), [](std::uint8_t b) { return b == kStxV1 || b == kStxV2; }));

    const Decoding r = decode_stream(stream);
    EXPECT_EQ(r.frames, (std::vector{inner_v2, inner_v1, after}));
    EXPECT_EQ(r.counters, (DecoderCounters{.bytes_in = stream.size(),
                                           .frames_out = 3,
                                           .bytes_discarded = wrapper.size() - payload.size(),
                                           .unverified = 1}));
  }
}

TEST(MavlinkDecoder, KnownMessagesOfEveryDialectAreVerifiedThoughNotDecoded) {
  // One message each from common.xml, ardupilotmega.xml (in both versions) and development.xml (whose ids need
  // MAVLink 2), then one of them damaged: the CRC of each is checked with its own CRC_EXTRA.
  struct Case {
    std::uint32_t id;
    std::uint8_t version;
  };
  std::vector<Message> sent;
  std::uint8_t seq = 0;
  for (const Case c : {Case{0, 1}, Case{0, 2}, Case{163, 1}, Case{163, 2}, Case{355, 2}}) {
    const MessageSpec* spec = message_spec(c.id);
    ASSERT_NE(spec, nullptr);
    ASSERT_FALSE(is_decoded(c.id));
    Bytes payload(spec->min_length);
    for (std::size_t i = 0; i < payload.size(); ++i) payload[i] = static_cast<std::uint8_t>(i + 1);
    sent.push_back(make_message(c.id, payload, {.version = c.version, .seq = seq++}));
  }
  Bytes stream;
  for (const Message& m : sent) {
    const Bytes frame = bytes_of(m);
    ASSERT_TRUE(stx_only_in_front(frame)) << m.msgid;
    append(stream, frame);
  }
  Bytes damaged = bytes_of(make_message(163, Bytes(28, 5), {.version = 1, .seq = seq}));
  damaged[10] ^= 0x01;
  ASSERT_TRUE(stx_only_in_front(damaged));
  append(stream, damaged);

  const Decoding r = decode_stream(stream);
  EXPECT_EQ(r.frames, sent);
  EXPECT_EQ(r.counters, (DecoderCounters{.bytes_in = stream.size(),
                                         .frames_out = sent.size(),
                                         .crc_failures = 1,
                                         .resyncs = 1,
                                         .bytes_discarded = damaged.size(),
                                         .unsupported = sent.size()}));
}

TEST(MavlinkDecoder, MavlinkOneLengthMustFitTheMessage) {
  // ATTITUDE has 28 payload bytes and no extensions. A MAVLink 1 frame of 30, though its CRC verifies, is not the
  // message its dialect defines. MAVLink 2 takes it: a newer sender may append extensions the table does not know.
  const Bytes payload(30, 0x11);
  const Bytes v1 = bytes_of(make_message(Attitude::kId, payload, {.version = 1}));
  ASSERT_TRUE(stx_only_in_front(v1));
  const Decoding r1 = decode_stream(v1);
  EXPECT_TRUE(r1.frames.empty());
  EXPECT_EQ(r1.counters, (DecoderCounters{.bytes_in = v1.size(), .resyncs = 1, .bytes_discarded = v1.size()}));

  const Message v2 = make_message(Attitude::kId, payload, {.version = 2});
  const Decoding r2 = decode_stream(bytes_of(v2));
  EXPECT_EQ(r2.frames, std::vector{v2});
  EXPECT_TRUE(std::holds_alternative<Attitude>(decode(r2.frames.at(0)).value()));
}

TEST(MavlinkDecoder, RandomBytesGiveNoFrames) {
  // Noise is full of STX bytes followed by headers of every kind; none may pass for a frame. mt19937_64's output is
  // fixed by the standard, so the bytes are the same on every platform.
  std::mt19937_64 random(20240917);
  Bytes noise(1 << 20);
  for (std::size_t i = 0; i < noise.size(); i += 8) {
    const std::uint64_t word = random();
    for (std::size_t k = 0; k < 8; ++k) noise[i + k] = static_cast<std::uint8_t>(word >> (8 * k));
  }
  for (const std::size_t chunk : {0u, 4096u}) {
    SCOPED_TRACE("chunk " + std::to_string(chunk));
    const Decoding r = decode_stream(noise, chunk);
    EXPECT_TRUE(r.frames.empty());
    EXPECT_EQ(r.counters.frames_out, 0u);
    EXPECT_EQ(r.counters.bytes_in, noise.size());
    EXPECT_EQ(r.counters.bytes_discarded, noise.size());
    // Every kind of candidate was met and counted, and none was a frame.
    EXPECT_GT(r.counters.unverified, 0u);
    EXPECT_GT(r.counters.crc_failures, 0u);
    EXPECT_GT(r.counters.resyncs, r.counters.crc_failures);
    EXPECT_EQ(r.counters.unsupported + r.counters.duplicates + r.counters.sequence_gaps, 0u);
  }
}

struct Sent {
  std::uint8_t sysid, compid, seq;
};

Bytes attitude_frames(const std::vector<Sent>& sent) {
  Bytes stream;
  for (const Sent& s : sent) append(stream, bytes_of(kAttitude, {.seq = s.seq, .sysid = s.sysid, .compid = s.compid}));
  return stream;
}

TEST(MavlinkDecoder, SequenceGapsPerSenderWithWrap) {
  const std::vector<Sent> sent = {
      {1, 1, 254},  {1, 200, 10}, {1, 1, 255}, {2, 1, 250}, {1, 1, 0},  // 255 -> 0 wraps without a gap
      {1, 200, 12},                                                     // one frame lost
      {1, 1, 1},    {2, 1, 3},                                          // 250 -> 3 across the wrap: 8 lost
  };
  const Decoding r = decode_stream(attitude_frames(sent));
  EXPECT_EQ(r.frames.size(), sent.size());
  EXPECT_EQ(r.counters.sequence_gaps, 2u);
  EXPECT_EQ(r.counters.frames_lost, 1u + 8u);
  EXPECT_EQ(r.counters.duplicates, 0u);
}

// An autopilot that reboots numbers its frames and counts its clock from zero again.
Bytes timed_frames(std::uint8_t first_seq, std::uint64_t first_time_us, int count) {
  Bytes stream;
  for (int k = 0; k < count; ++k) {
    HighresImu imu = kHighres;
    imu.time_usec = first_time_us + 1000u * static_cast<std::uint64_t>(k);
    Attitude attitude = kAttitude;
    attitude.time_boot_ms = static_cast<std::uint32_t>(imu.time_usec / 1000);
    append(stream, bytes_of(imu, {.seq = static_cast<std::uint8_t>(first_seq + 2 * k)}));
    append(stream, bytes_of(attitude, {.seq = static_cast<std::uint8_t>(first_seq + 2 * k + 1)}));
  }
  return stream;
}

TEST(MavlinkDecoder, ARebootedSenderIsARestartNotALoss) {
  Bytes stream = timed_frames(100, 600'000'000, 20);  // seq 100..139, ten minutes after boot
  append(stream, timed_frames(0, 1'000, 20));         // seq 0..39 from boot again
  const Decoding r = decode_stream(stream);
  ASSERT_EQ(r.frames.size(), 80u);
  EXPECT_EQ(r.counters.device_restarts, 1u);
  EXPECT_EQ(r.counters.sequence_gaps, 0u);
  EXPECT_EQ(r.counters.frames_lost, 0u);
  EXPECT_EQ(r.frames[39].clock_epoch, 0u);
  EXPECT_EQ(r.frames[40].clock_epoch, 1u);
  const std::optional<Sample> after = to_sample(r.frames[40], nullptr);
  ASSERT_TRUE(after);
  EXPECT_EQ(after->clock_epoch, 1u);
  EXPECT_EQ(after->device_time_us, 1'000);
}

TEST(MavlinkDecoder, AClockThatStepsBackBetweenConsecutiveFramesIsNoRestart) {
  // The next number with an earlier time is a glitch of the clock (the estimator drops that sample); a restart
  // needs the numbering to start again as well.
  Bytes stream = timed_frames(10, 5'000'000, 5);   // seq 10..19
  append(stream, timed_frames(20, 4'000'000, 5));  // seq 20..29, its clock a second back
  const Decoding r = decode_stream(stream);
  EXPECT_EQ(r.frames.size(), 20u);
  EXPECT_EQ(r.counters.device_restarts, 0u);
  EXPECT_EQ(r.counters.sequence_gaps, 0u);
  EXPECT_EQ(r.frames.back().clock_epoch, 0u);
}

TEST(MavlinkDecoder, RepeatedSequenceNumberFromAComponentIsADuplicate) {
  // A telemetry radio that retransmits delivers a frame twice. Another component may use the same number meanwhile.
  const std::vector<Sent> sent = {
      {1, 1, 5},   {1, 1, 5},  // a repeat
      {1, 200, 5},             // the same number from another component: its own first frame
      {1, 1, 5},               // still (1, 1)'s previous number: a repeat
      {1, 200, 6}, {1, 1, 6},  // both next in line
  };
  const Bytes stream = attitude_frames(sent);
  const Decoding r = decode_stream(stream);
  std::vector<std::tuple<int, int, int>> received;
  for (const Message& m : r.frames) received.emplace_back(m.sysid, m.compid, m.seq);
  EXPECT_EQ(received, (std::vector<std::tuple<int, int, int>>{{1, 1, 5}, {1, 200, 5}, {1, 200, 6}, {1, 1, 6}}));
  EXPECT_EQ(r.counters, (DecoderCounters{.bytes_in = stream.size(),
                                         .frames_out = 4,
                                         .bytes_discarded = 2 * stream.size() / sent.size(),
                                         .duplicates = 2}));
}

TEST(MavlinkDecoder, FinishFindsAFrameInsideACutOffFalseStart) {
  // Near the end of the stream a noise STX starts a header whose length claims more bytes than remain: only the end
  // of the stream refutes it, and the frame inside it comes out of finish().
  const Bytes first = bytes_of(kHighres, {.seq = 0}), hidden = bytes_of(kAttitude, {.seq = 1});
  const Bytes false_start = {kStxV2, 200, 0, 0, 9, 1, 1, Attitude::kId, 0, 0};
  Bytes stream = first;
  append(stream, false_start);
  append(stream, hidden);
  ASSERT_TRUE(stx_only_in_front(hidden));

  Decoder decoder;
  std::vector<Message> messages;
  decoder.feed(stream, messages);
  EXPECT_EQ(messages, std::vector{make_message(kHighres, {.seq = 0})});
  decoder.finish(messages);
  const Decoding whole{messages, decoder.counters()};
  EXPECT_EQ(whole.frames, (std::vector{make_message(kHighres, {.seq = 0}), make_message(kAttitude, {.seq = 1})}));
  EXPECT_EQ(whole.counters,
            (DecoderCounters{
                .bytes_in = stream.size(), .frames_out = 2, .resyncs = 1, .bytes_discarded = false_start.size()}));
  EXPECT_EQ(harness::first_split_that_differs(Decoder{}, stream, whole), std::nullopt);
}

TEST(MavlinkDecoder, EveryByteIsInAFrameOrDiscarded) {
  Bytes stream = troubled_stream();
  for (std::size_t i = 0; i < 300; ++i) stream.push_back(static_cast<std::uint8_t>(i * 37 + 11));
  append(stream, troubled_stream());
  for (std::size_t chunk : {0u, 1u, 7u, 100u}) {
    const Decoding r = decode_stream(stream, chunk);
    EXPECT_EQ(r.counters.bytes_in, stream.size());
    EXPECT_EQ(r.counters.frames_out, r.frames.size());
    EXPECT_EQ(r.counters.bytes_in, frame_bytes(r.frames) + r.counters.bytes_discarded) << "chunk " << chunk;
  }
}

// ---- JSON and samples ----

TEST(MavlinkJson, HeaderAndDecodedFields) {
  const Attitude attitude{4000010, 0.5f, -0.25f, 3.0f, 0.125f, -0.0625f, 1.5f};  // binary fractions: exact in JSON
  const nlohmann::json j = make_message(attitude, {.seq = 3, .sysid = 1, .compid = 190});
  EXPECT_EQ(j, nlohmann::json::parse(R"({"protocol":"mavlink","version":2,"seq":3,"sysid":1,"compid":190,"msgid":30,
      "len":28,"signed":false,"name":"ATTITUDE","time_boot_ms":4000010,"roll":0.5,"pitch":-0.25,"yaw":3.0,
      "rollspeed":0.125,"pitchspeed":-0.0625,"yawspeed":1.5})"));
}

TEST(MavlinkSample, HighresImuIsSiWithMagInMicrotesla) {
  const auto s = to_sample(make_message(kHighres, {.seq = 9}), nullptr);
  ASSERT_TRUE(s);
  EXPECT_EQ(s->seq, 9u);
  EXPECT_EQ(s->device_time_us, 1'700'000'123'456);
  EXPECT_EQ(s->accel, (std::array<double, 3>{0.125, -0.5, -9.80665f}));
  EXPECT_EQ(s->gyro, (std::array<double, 3>{0.01f, -0.02f, 0.5f}));
  ASSERT_TRUE(s->has_mag);
  EXPECT_EQ(s->mag, (std::array<double, 3>{25.0, -6.25, 50.0}));  // 0.25, -0.0625, 0.5 gauss
  ASSERT_TRUE(s->has_temperature);
  EXPECT_EQ(s->temperature_c, 31.5);
  EXPECT_FALSE(s->has_raw);

  HighresImu stale = kHighres;
  stale.fields_updated = 0x003F;  // accelerometer and gyro fresh; magnetometer and temperature repeated
  const auto t = to_sample(make_message(stale, {}), nullptr);
  ASSERT_TRUE(t);
  EXPECT_FALSE(t->has_mag);
  EXPECT_EQ(t->mag, (std::array<double, 3>{}));
  EXPECT_FALSE(t->has_temperature);
}

TEST(MavlinkSample, ScaledImuUnits) {
  const ScaledImu m{.time_boot_ms = 1234,
                    .xacc = 1000,
                    .yacc = -500,
                    .zacc = -1000,
                    .xgyro = 1000,
                    .ygyro = -250,
                    .zgyro = 2,
                    .xmag = 500,
                    .ymag = -10,
                    .zmag = 0,
                    .temperature = 2512};
  const auto s = to_sample(make_message(m, {}), nullptr);
  ASSERT_TRUE(s);
  EXPECT_EQ(s->device_time_us, 1'234'000);
  EXPECT_DOUBLE_EQ(s->accel[0], 9.80665);  // 1000 mG is one standard gravity
  EXPECT_DOUBLE_EQ(s->accel[1], -9.80665 / 2);
  EXPECT_DOUBLE_EQ(s->accel[2], -9.80665);
  EXPECT_DOUBLE_EQ(s->gyro[0], 1.0);
  EXPECT_DOUBLE_EQ(s->gyro[1], -0.25);
  EXPECT_DOUBLE_EQ(s->gyro[2], 0.002);
  EXPECT_TRUE(s->has_mag);
  EXPECT_DOUBLE_EQ(s->mag[0], 50.0);  // 500 mgauss = 0.5 gauss = 50 uT
  EXPECT_DOUBLE_EQ(s->mag[1], -1.0);
  EXPECT_DOUBLE_EQ(s->mag[2], 0.0);
  EXPECT_TRUE(s->has_temperature);
  EXPECT_DOUBLE_EQ(s->temperature_c, 25.12);

  ScaledImu no_temperature = m;
  no_temperature.temperature = 0;  // MAVLink's "not provided"
  EXPECT_FALSE(to_sample(make_message(no_temperature, {}), nullptr)->has_temperature);
}

// SCALED_IMU2 and SCALED_IMU3 are a second and third IMU in SCALED_IMU's units: mG, mrad/s, mgauss, cdegC.
TEST(MavlinkSample, ScaledImu2AndScaledImu3InScaledImusUnits) {
  const ScaledImu2 second{.time_boot_ms = 60'000,
                          .xacc = 2000,
                          .yacc = -3,
                          .zacc = -998,
                          .xgyro = -1500,
                          .ygyro = 7,
                          .zgyro = 0,
                          .xmag = 250,
                          .ymag = -4,
                          .zmag = 1,
                          .temperature = 1};
  const Message m = make_message(second, {.seq = 3});
  EXPECT_EQ(m.msgid, 116u);
  const Bytes bytes = bytes_of(m);
  const Decoding r = decode_stream(bytes);
  ASSERT_EQ(r.frames.size(), 1u);
  EXPECT_EQ(r.counters.unsupported, 0u);
  EXPECT_EQ(std::get<ScaledImu2>(decode(r.frames[0]).value()), second);
  const auto s = to_sample(r.frames[0], nullptr);
  ASSERT_TRUE(s);
  EXPECT_EQ(s->device_time_us, 60'000'000);
  EXPECT_DOUBLE_EQ(s->accel[0], 2 * 9.80665);
  EXPECT_DOUBLE_EQ(s->accel[1], -3 * 9.80665 / 1000);
  EXPECT_DOUBLE_EQ(s->accel[2], -998 * 9.80665 / 1000);
  EXPECT_DOUBLE_EQ(s->gyro[0], -1.5);
  EXPECT_DOUBLE_EQ(s->gyro[1], 0.007);
  EXPECT_DOUBLE_EQ(s->mag[0], 25.0);  // 250 mgauss = 25 uT
  EXPECT_DOUBLE_EQ(s->mag[2], 0.1);
  EXPECT_TRUE(s->has_temperature);
  EXPECT_DOUBLE_EQ(s->temperature_c, 0.01);  // 0 degC is sent as 1
  EXPECT_EQ(imu_source(m), (ImuSource{.msgid = 116, .sysid = 1, .compid = 1, .id = 0}));
  EXPECT_EQ(describe(*imu_source(m)), "SCALED_IMU2 from system 1, component 1");

  const ScaledImu3 third{.time_boot_ms = 5, .xacc = 1000};
  const auto t = to_sample(make_message(third, {}), nullptr);
  ASSERT_TRUE(t);
  EXPECT_DOUBLE_EQ(t->accel[0], 9.80665);
  EXPECT_EQ(nlohmann::json(make_message(third, {}))["name"], "SCALED_IMU3");
}

TEST(MavlinkSample, EachImuIsASource) {
  HighresImu second_highres = kHighres;
  second_highres.id = 1;
  EXPECT_EQ(imu_source(make_message(second_highres, {.sysid = 2, .compid = 3})),
            (ImuSource{.msgid = 105, .sysid = 2, .compid = 3, .id = 1}));
  EXPECT_EQ(describe(*imu_source(make_message(second_highres, {}))), "HIGHRES_IMU id 1 from system 1, component 1");
  EXPECT_EQ(imu_source(make_message(kRaw, {})), (ImuSource{.msgid = 27, .sysid = 1, .compid = 1, .id = kRaw.id}));
  EXPECT_EQ(imu_source(make_message(kScaled, {})), (ImuSource{.msgid = 26, .sysid = 1, .compid = 1}));
  EXPECT_EQ(imu_source(make_message(kAttitude, {})), std::nullopt);
  EXPECT_EQ(imu_source(make_message(LocalPositionNed{}, {})), std::nullopt);
}

// What a reader of a log of frames gets for the bytes at a frame's start: the decoder's verdict on them.
TEST(MavlinkFrame, CheckFrameJudgesAsTheDecoderDoes) {
  using Status = FrameCheck::Status;
  const Bytes frame = bytes_of(kScaled, {.seq = 1});
  EXPECT_EQ(check_frame(frame).status, Status::frame);
  EXPECT_EQ(check_frame(frame).size, frame.size());
  Bytes longer = frame;
  append(longer, bytes_of(kAttitude, {.seq = 2}));
  EXPECT_EQ(check_frame(longer).size, frame.size());  // the first frame only
  EXPECT_EQ(check_frame(std::span(frame).first(frame.size() - 1)).status, Status::cut_short);
  EXPECT_EQ(check_frame(std::span(frame).first(3)).status, Status::cut_short);
  Bytes flipped = frame;
  flipped[12] ^= 0x10;
  EXPECT_EQ(check_frame(flipped).status, Status::bad_crc);
  EXPECT_EQ(check_frame(Bytes{0x00, 0x01}).status, Status::malformed);
  EXPECT_EQ(check_frame(Bytes{}).status, Status::malformed);
  Bytes unknown = bytes_of(make_message(kUnknownId, Bytes{1, 2, 3}, {}));
  EXPECT_EQ(check_frame(unknown).status, Status::unverified);
  EXPECT_EQ(check_frame(unknown).size, unknown.size());
  EXPECT_EQ(check_frame(bytes_of(kHighres, {.version = 1})).status, Status::frame);
  EXPECT_EQ(check_frame(bytes_of(kHighres, {.sign = true})).size, 10 + 63 + 2 + 13u);
}

TEST(MavlinkSample, RawImuGoesThroughTheCalibration) {
  const Message m = make_message(kRaw, {.seq = 4});
  EXPECT_EQ(to_sample(m, nullptr), std::nullopt);

  Calibration c;
  c.accel.scale = {0.5, 0.25, 2.0};
  c.accel.offset = {50, 43, 27};
  c.gyro.scale.fill(0.001);
  c.mag.scale.fill(0.1);
  const auto s = to_sample(m, &c);
  ASSERT_TRUE(s);
  EXPECT_EQ(s->seq, 4u);
  EXPECT_EQ(s->device_time_us, 987654321);
  EXPECT_EQ(s->accel, (std::array<double, 3>{1000.0, 500.0, 3000.0}));  // scale * (raw - offset)
  EXPECT_DOUBLE_EQ(s->gyro[2], 0.3);
  EXPECT_DOUBLE_EQ(s->mag[2], -18.0);
  EXPECT_TRUE(s->has_temperature);
  EXPECT_DOUBLE_EQ(s->temperature_c, -15.5);  // RAW_IMU's temperature is cdegC, whatever the calibration says
  EXPECT_TRUE(s->has_raw);
  EXPECT_EQ(s->raw, (std::array<std::int32_t, 10>{2050, 2043, 1527, -12, 5, 300, 210, -95, -180, -1550}));
}

TEST(MavlinkSample, OtherMessagesAreNotSamples) {
  Calibration c;
  EXPECT_EQ(to_sample(make_message(kAttitude, {}), &c), std::nullopt);
  EXPECT_EQ(to_sample(decode_stream(heartbeat(0)).frames.at(0), &c), std::nullopt);
}

}  // namespace
}  // namespace imubridge::protocol::mavlink

namespace imubridge::protocol::mavlink {
namespace {

// The decoder reads each frame's clock straight off the payload (clock_field), without decoding it: for every message
// kind that has one, the value read is the one the typed decoding gives.
TEST(MavlinkClock, ReadOffThePayloadItIsTheDecodedMessagesOwn) {
  const HighresImu highres{.time_usec = 0x0123456789ABCDEFull, .xacc = 1.5f};
  const Attitude attitude{.time_boot_ms = 4'000'001u, .roll = 0.25f};
  for (const Decoded& message : {Decoded{highres}, Decoded{attitude}}) {
    const std::vector<std::uint8_t> payload = encode_payload(message);
    const std::optional<ClockField> clock = clock_field(message_id(message));
    ASSERT_TRUE(clock.has_value()) << message_id(message);
    const std::uint64_t expected = std::visit(
        []<typename M>(const M& m) -> std::uint64_t {
          if constexpr (requires { m.time_usec; }) {
            return m.time_usec;
          } else if constexpr (requires { m.time_boot_ms; }) {
            return std::uint64_t{m.time_boot_ms} * 1000;
          } else {
            ADD_FAILURE() << M::kName << " has no clock";
            return 0;
          }
        },
        message);
    EXPECT_EQ(read_clock(payload.data(), *clock), expected) << message_id(message);
  }
  EXPECT_EQ(clock_field(HighresImu::kId)->size, 8u);
  EXPECT_EQ(clock_field(Attitude::kId)->to_us, 1000u);
  EXPECT_NE(clock_field(HighresImu::kId)->slot, clock_field(Attitude::kId)->slot);
  EXPECT_FALSE(clock_field(0).has_value());  // HEARTBEAT: no clock
  EXPECT_FALSE(clock_field(ExtendedSysState::kId).has_value());
}

// The autopilot's land detector: both bytes read back; a MAVLink 2 sender truncates a landed_state of 0 (undefined)
// away, which reads back as 0.
TEST(MavlinkExtendedSysState, CarriesTheLandDetectorsState) {
  for (const auto state : {LandedState::undefined, LandedState::on_ground, LandedState::in_air, LandedState::landing}) {
    const ExtendedSysState sent{.vtol_state = 0, .landed_state = static_cast<std::uint8_t>(state)};
    const Message m = make_message(sent, {});
    EXPECT_EQ(m.msgid, 245u);
    const std::optional<Decoded> back = decode(m);
    ASSERT_TRUE(back.has_value());
    EXPECT_EQ(std::get<ExtendedSysState>(*back), sent);
  }
}

}  // namespace
}  // namespace imubridge::protocol::mavlink
