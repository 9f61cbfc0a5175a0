#pragma once
// Raw IMU counts <-> SI units. The formulas and the reference board: docs/protocol.md, section "Calibration".
#include <array>
#include <cstdint>
#include <optional>

#include "protocol/imu_frame.hpp"
#include "protocol/sample.hpp"

namespace imubridge::protocol {

// si = sign[i] * scale[src] * (raw[src] - offset[src]) with src = source_axis[i]: scale, offset and an axis map.
// scale and offset belong to the sensor's own axes; source_axis and sign place them on the IMU's axes.
struct AxisCalibration {
  std::array<double, 3> scale{1, 1, 1}, offset{0, 0, 0};
  std::array<std::uint8_t, 3> source_axis{0, 1, 2};
  std::array<std::int8_t, 3> sign{1, 1, 1};

  bool operator==(const AxisCalibration&) const = default;

  // source_axis is a permutation of 0, 1, 2; every sign is +1 or -1; scales are finite and non-zero; offsets
  // finite. Whoever builds a calibration from outside input checks this: the conversions assume it.
  bool valid() const;
};

struct Calibration {
  AxisCalibration accel, gyro, mag;                        // to m/s^2, rad/s, microtesla
  double temperature_scale = 1, temperature_offset_c = 0;  // celsius = offset + scale * raw

  static Calibration reference_board();  // the paper's IMU board: ADXL327 + ITG3200 + HMC5843
  bool valid() const;
  bool operator==(const Calibration&) const = default;  // exact: a snapshot must give back the very doubles

  // Fills accel/gyro/mag/temperature, raw and the has_* flags; the caller fills link, sequence and times.
  Sample to_sample(const imu::ImuRaw& raw) const;
  // The inverse, for the simulator: rounds to the nearest count and saturates to int16.
  imu::ImuRaw to_counts(const std::array<double, 3>& accel, const std::array<double, 3>& gyro,
                        const std::array<double, 3>& mag, double temperature_c) const;
};

// A decoded IMU sample frame as a Sample (sequence unwrapped, device time from the frame); nothing for frames
// that carry no measurement (velocity estimates).
std::optional<Sample> to_sample(const imu::Frame& frame, const Calibration& calibration, const SourceKey& source,
                                std::int64_t recv_mono_ns);

}  // namespace imubridge::protocol
