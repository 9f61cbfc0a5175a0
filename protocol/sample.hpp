#pragma once
// One IMU measurement in SI units, whatever protocol carried it: the "samples" stage of the pipeline.
#include <array>
#include <cstdint>

namespace imubridge::protocol {

// Which link a sample came from (a serial port, or an XBee radio heard through one). While recording it is the
// link's row id in the store (SQLite's 64-bit integer), so samples, estimates and events all name a link the same way.
using LinkId = std::int64_t;

struct Sample {
  LinkId link_id = 0;               // which link (serial port / XBee source) it came from
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
