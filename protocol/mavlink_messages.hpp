#pragma once
// The MAVLink messages imubridge reads, as common.xml defines them, and the CRC_EXTRA of every common.xml message.
// Payload layouts only: framing is protocol/mavlink.hpp. Units and conversion to samples: docs/protocol.md.
#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>
#include <variant>
#include <vector>

#include "protocol/byte_order.hpp"

namespace imubridge::protocol::mavlink {

// What a message's XML definition tells a receiver checking its frames: the CRC_EXTRA that ends its CRC, and its
// payload length with the base fields only (what MAVLink 1 senders send) and with the extensions too.
struct MessageSpec {
  std::uint32_t id;
  std::uint8_t crc_extra;
  std::uint8_t min_length, max_length;
  std::string_view name;
};

// Every message of the common, ardupilotmega and development dialects and of the dialects they include, sorted by
// id: protocol/mavlink_message_specs.cpp, generated from MAVLink's XML by scripts/generate-mavlink-crc-extra.
std::span<const MessageSpec> message_specs();
// The spec of `msgid`, or nullptr for an id outside those dialects: its frames cannot be verified.
const MessageSpec* message_spec(std::uint32_t msgid);
// The CRC_EXTRA of `msgid`, or nothing for an id outside those dialects.
std::optional<std::uint8_t> crc_extra(std::uint32_t msgid);

// Each message lists its fields in wire order through for_each_field(m, f), which calls f(name, field): MAVLink
// sorts the base fields by type size (stable), then appends the extension fields in definition order. Extension
// fields read 0 when the sender left them out (MAVLink 1, or a sender that predates them). A field is a scalar or a
// std::array of them (MAVLink's float[4] and the like).

struct HighresImu {
  static constexpr std::uint32_t kId = 105;
  static constexpr std::string_view kName = "HIGHRES_IMU";
  static constexpr std::size_t kBaseLength = 62, kLength = 63;  // payload bytes without / with the extensions

  std::uint64_t time_usec = 0;
  float xacc = 0, yacc = 0, zacc = 0;         // m/s^2
  float xgyro = 0, ygyro = 0, zgyro = 0;      // rad/s
  float xmag = 0, ymag = 0, zmag = 0;         // gauss
  float abs_pressure = 0, diff_pressure = 0;  // hPa
  float pressure_alt = 0;                     // m
  float temperature = 0;                      // degC
  std::uint16_t fields_updated = 0;           // HIGHRES_IMU_UPDATED_FLAGS: bit i set = field i (xacc = 0) is fresh
  std::uint8_t id = 0;                        // extension: which IMU (0 = IMU1)

  template <typename Self, typename F>
  static constexpr void for_each_field(Self& m, F&& f) {
    f("time_usec", m.time_usec);
    f("xacc", m.xacc), f("yacc", m.yacc), f("zacc", m.zacc);
    f("xgyro", m.xgyro), f("ygyro", m.ygyro), f("zgyro", m.zgyro);
    f("xmag", m.xmag), f("ymag", m.ymag), f("zmag", m.zmag);
    f("abs_pressure", m.abs_pressure), f("diff_pressure", m.diff_pressure), f("pressure_alt", m.pressure_alt);
    f("temperature", m.temperature);
    f("fields_updated", m.fields_updated);
    f("id", m.id);
  }
  friend bool operator==(const HighresImu&, const HighresImu&) = default;
};

// SCALED_IMU, SCALED_IMU2 and SCALED_IMU3: one layout for an autopilot's first, second and third IMU, told apart by
// their message id.
template <std::uint32_t Id>
struct ScaledImuOf {
  static constexpr std::uint32_t kId = Id;
  static constexpr std::string_view kName = Id == 26 ? "SCALED_IMU" : Id == 116 ? "SCALED_IMU2" : "SCALED_IMU3";
  static constexpr std::size_t kBaseLength = 22, kLength = 24;

  std::uint32_t time_boot_ms = 0;
  std::int16_t xacc = 0, yacc = 0, zacc = 0;     // mG
  std::int16_t xgyro = 0, ygyro = 0, zgyro = 0;  // mrad/s
  std::int16_t xmag = 0, ymag = 0, zmag = 0;     // mgauss
  std::int16_t temperature = 0;                  // extension: cdegC, 0 = not provided (0 degC is sent as 1)

  template <typename Self, typename F>
  static constexpr void for_each_field(Self& m, F&& f) {
    f("time_boot_ms", m.time_boot_ms);
    f("xacc", m.xacc), f("yacc", m.yacc), f("zacc", m.zacc);
    f("xgyro", m.xgyro), f("ygyro", m.ygyro), f("zgyro", m.zgyro);
    f("xmag", m.xmag), f("ymag", m.ymag), f("zmag", m.zmag);
    f("temperature", m.temperature);
  }
  friend bool operator==(const ScaledImuOf&, const ScaledImuOf&) = default;
};
using ScaledImu = ScaledImuOf<26>;
using ScaledImu2 = ScaledImuOf<116>;
using ScaledImu3 = ScaledImuOf<129>;

struct RawImu {
  static constexpr std::uint32_t kId = 27;
  static constexpr std::string_view kName = "RAW_IMU";
  static constexpr std::size_t kBaseLength = 26, kLength = 29;

  std::uint64_t time_usec = 0;
  std::int16_t xacc = 0, yacc = 0, zacc = 0;  // sensor counts
  std::int16_t xgyro = 0, ygyro = 0, zgyro = 0;
  std::int16_t xmag = 0, ymag = 0, zmag = 0;
  std::uint8_t id = 0;           // extension: which IMU (0 = IMU1)
  std::int16_t temperature = 0;  // extension: cdegC, 0 = not provided (0 degC is sent as 1)

  template <typename Self, typename F>
  static constexpr void for_each_field(Self& m, F&& f) {
    f("time_usec", m.time_usec);
    f("xacc", m.xacc), f("yacc", m.yacc), f("zacc", m.zacc);
    f("xgyro", m.xgyro), f("ygyro", m.ygyro), f("zgyro", m.zgyro);
    f("xmag", m.xmag), f("ymag", m.ymag), f("zmag", m.zmag);
    f("id", m.id);
    f("temperature", m.temperature);
  }
  friend bool operator==(const RawImu&, const RawImu&) = default;
};

struct Attitude {
  static constexpr std::uint32_t kId = 30;
  static constexpr std::string_view kName = "ATTITUDE";
  static constexpr std::size_t kBaseLength = 28, kLength = 28;

  std::uint32_t time_boot_ms = 0;
  float roll = 0, pitch = 0, yaw = 0;                 // rad
  float rollspeed = 0, pitchspeed = 0, yawspeed = 0;  // rad/s

  template <typename Self, typename F>
  static constexpr void for_each_field(Self& m, F&& f) {
    f("time_boot_ms", m.time_boot_ms);
    f("roll", m.roll), f("pitch", m.pitch), f("yaw", m.yaw);
    f("rollspeed", m.rollspeed), f("pitchspeed", m.pitchspeed), f("yawspeed", m.yawspeed);
  }
  friend bool operator==(const Attitude&, const Attitude&) = default;
};

struct AttitudeQuaternion {
  static constexpr std::uint32_t kId = 31;
  static constexpr std::string_view kName = "ATTITUDE_QUATERNION";
  static constexpr std::size_t kBaseLength = 32, kLength = 48;

  std::uint32_t time_boot_ms = 0;
  float q1 = 0, q2 = 0, q3 = 0, q4 = 0;               // w, x, y, z: body (FRD) -> NED; (1, 0, 0, 0) is level north
  float rollspeed = 0, pitchspeed = 0, yawspeed = 0;  // rad/s
  std::array<float, 4> repr_offset_q{};               // extension: a display offset (w, x, y, z), 0s if unsupported

  template <typename Self, typename F>
  static constexpr void for_each_field(Self& m, F&& f) {
    f("time_boot_ms", m.time_boot_ms);
    f("q1", m.q1), f("q2", m.q2), f("q3", m.q3), f("q4", m.q4);
    f("rollspeed", m.rollspeed), f("pitchspeed", m.pitchspeed), f("yawspeed", m.yawspeed);
    f("repr_offset_q", m.repr_offset_q);
  }
  friend bool operator==(const AttitudeQuaternion&, const AttitudeQuaternion&) = default;
};

struct LocalPositionNed {
  static constexpr std::uint32_t kId = 32;
  static constexpr std::string_view kName = "LOCAL_POSITION_NED";
  static constexpr std::size_t kBaseLength = 28, kLength = 28;

  std::uint32_t time_boot_ms = 0;
  float x = 0, y = 0, z = 0;     // m, NED from the autopilot's local origin
  float vx = 0, vy = 0, vz = 0;  // m/s, NED

  template <typename Self, typename F>
  static constexpr void for_each_field(Self& m, F&& f) {
    f("time_boot_ms", m.time_boot_ms);
    f("x", m.x), f("y", m.y), f("z", m.z);
    f("vx", m.vx), f("vy", m.vy), f("vz", m.vz);
  }
  friend bool operator==(const LocalPositionNed&, const LocalPositionNed&) = default;
};

// MAV_LANDED_STATE: what an autopilot's land detector says.
enum class LandedState : std::uint8_t { undefined = 0, on_ground = 1, in_air = 2, takeoff = 3, landing = 4 };

struct ExtendedSysState {
  static constexpr std::uint32_t kId = 245;
  static constexpr std::string_view kName = "EXTENDED_SYS_STATE";
  static constexpr std::size_t kBaseLength = 2, kLength = 2;

  std::uint8_t vtol_state = 0;    // MAV_VTOL_STATE
  std::uint8_t landed_state = 0;  // MAV_LANDED_STATE (LandedState)

  template <typename Self, typename F>
  static constexpr void for_each_field(Self& m, F&& f) {
    f("vtol_state", m.vtol_state), f("landed_state", m.landed_state);
  }
  friend bool operator==(const ExtendedSysState&, const ExtendedSysState&) = default;
};

// The messages that get typed fields; every other id is carried as payload bytes only.
using Decoded = std::variant<HighresImu, ScaledImu, ScaledImu2, ScaledImu3, RawImu, Attitude, AttitudeQuaternion,
                             LocalPositionNed, ExtendedSysState>;

bool is_decoded(std::uint32_t msgid);

// Where a decoded message carries its sender's clock (time_usec, or time_boot_ms): read off for_each_field's wire
// order, so that the decoder reads a frame's clock without decoding the frame.
struct ClockField {
  std::size_t slot = 0;     // the message's index in Decoded: one clock per message kind and sender
  std::size_t offset = 0;   // payload bytes before it
  std::size_t size = 0;     // 8 (time_usec) or 4 (time_boot_ms)
  std::uint64_t to_us = 1;  // 1, or 1000 for milliseconds
};
inline constexpr std::size_t kClockSlots = std::variant_size_v<Decoded>;
// nullopt for an id without a clock, decoded or not.
std::optional<ClockField> clock_field(std::uint32_t msgid);
// The clock in microseconds, from a payload zero-filled beyond what was received (as Message's is). Inline: the
// decoder reads one for most frames.
inline std::uint64_t read_clock(const std::uint8_t* payload, const ClockField& field) {
  const std::uint64_t ticks = field.size == 8 ? load_le<std::uint64_t>(payload + field.offset)
                                              : std::uint64_t{load_le<std::uint32_t>(payload + field.offset)};
  return ticks * field.to_us;
}

// The typed fields of a payload as received; bytes missing at the end (MAVLink 2 truncation) read as zero.
std::optional<Decoded> decode_payload(std::uint32_t msgid, std::span<const std::uint8_t> payload);

// The message's full payload, or only its base fields when `extensions` is false (what MAVLink 1 carries).
std::vector<std::uint8_t> encode_payload(const Decoded& message, bool extensions = true);

std::uint32_t message_id(const Decoded& message);

}  // namespace imubridge::protocol::mavlink
