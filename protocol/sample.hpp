#pragma once
// One IMU measurement in SI units, whatever protocol carried it: the "samples" stage of the pipeline.
#include <array>
#include <compare>
#include <cstdint>
#include <optional>

namespace imubridge::protocol {

// A link's row id in a store (SQLite's 64-bit integer): where its samples, estimates and events are stored.
using LinkId = std::int64_t;

// Which stream of samples a sample belongs to, in terms the session itself knows: the link it came through (its
// index in the session, the order its links were configured and recorded in) and, on an XBee link, the radio that
// sent it (its 64-bit source address), each radio being a vehicle of its own. The same bytes give the same keys live
// and in replay, recorded or not, so nothing keyed by them (a filter, an output's stream) changes when a recording
// begins, rotates or stops.
struct SourceKey {
  std::uint32_t link = 0;
  std::optional<std::uint64_t> radio{};  // none: the link's own samples
  friend auto operator<=>(const SourceKey&, const SourceKey&) = default;
};

struct Sample {
  SourceKey source{};  // which link (and XBee radio) it came from: the pipeline knows a sample by this
  // The store link it is stored under: set by the recording as it stores the sample (pipeline::LinkRecorder) and by
  // the store's readers. The pipeline never reads it.
  LinkId link_id = 0;
  std::uint64_t seq = 0;            // sequence number, unwrapped to 64 bits by the receiver
  std::int64_t device_time_us = 0;  // timestamp the device put on the measurement
  std::uint32_t clock_epoch = 0;    // the device's restarts seen before it: device_time_us counts from the last one
  std::int64_t recv_mono_ns = 0;    // ground-station monotonic time the completing byte chunk arrived
  std::array<double, 3> accel{};    // specific force, m/s^2, IMU axes
  std::array<double, 3> gyro{};     // angular rate, rad/s, IMU axes
  std::array<double, 3> mag{};      // magnetic field, microtesla, IMU axes (zero when has_mag is false)
  double temperature_c = 0.0;
  bool has_mag = false;
  bool has_temperature = false;
  // Raw sensor counts as they travelled on the wire (accel xyz, gyro xyz, mag xyz, temperature),
  // kept beside the SI values so a calibration can be redone later. has_raw is false for protocols
  // that carry SI values directly (MAVLink HIGHRES_IMU).
  std::array<std::int32_t, 10> raw{};
  bool has_raw = false;
};

}  // namespace imubridge::protocol
