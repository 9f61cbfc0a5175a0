#include "protocol/calibration.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "protocol/units.hpp"

namespace imubridge::protocol {
namespace {

std::array<double, 3> to_si(const AxisCalibration& c, const std::array<std::int16_t, 3>& raw) {
  std::array<double, 3> si{};
  for (std::size_t i = 0; i < 3; ++i) {
    const std::size_t src = c.source_axis[i];
    si[i] = c.sign[i] * c.scale[src] * (raw[src] - c.offset[src]);
  }
  return si;
}

std::int16_t to_count(double x) {
  if (std::isnan(x)) return 0;  // NaN has no count; casting it would be undefined behaviour
  return static_cast<std::int16_t>(std::clamp(std::round(x), -32768.0, 32767.0));
}

std::array<std::int16_t, 3> to_raw(const AxisCalibration& c, const std::array<double, 3>& si) {
  std::array<std::int16_t, 3> raw{};
  for (std::size_t i = 0; i < 3; ++i) {
    const std::size_t src = c.source_axis[i];
    raw[src] = to_count(c.offset[src] + c.sign[i] * si[i] / c.scale[src]);  // sign is +-1: its own inverse
  }
  return raw;
}

}  // namespace

bool AxisCalibration::valid() const {
  std::array<bool, 3> used{};
  for (std::size_t i = 0; i < 3; ++i) {
    if (source_axis[i] > 2 || used[source_axis[i]]) return false;
    used[source_axis[i]] = true;
    if (sign[i] != 1 && sign[i] != -1) return false;
    if (!std::isfinite(scale[i]) || scale[i] == 0 || !std::isfinite(offset[i])) return false;
  }
  return true;
}

bool Calibration::valid() const {
  return accel.valid() && gyro.valid() && mag.valid() && std::isfinite(temperature_scale) && temperature_scale != 0 &&
         std::isfinite(temperature_offset_c);
}

Calibration Calibration::reference_board() {
  Calibration c;
  // ADXL327: 420 mV/g at a 3.3 V supply, 0 g at mid-supply, read by a 12-bit ADC referenced to the same 3.3 V.
  c.accel.scale.fill(kStandardGravity * 3.3 / (0.42 * 4096));
  c.accel.offset.fill(2048);
  // ITG3200: 14.375 LSB per deg/s.
  c.gyro.scale.fill(std::numbers::pi / 180 / 14.375);
  // HMC5843: 1300 counts per gauss (its default gain).
  c.mag.scale.fill(kMicroteslaPerGauss / 1300);
  // ITG3200 temperature sensor: -13200 counts at 35 C, 280 counts per C.
  c.temperature_scale = 1.0 / 280;
  c.temperature_offset_c = 35 + 13200.0 / 280;
  return c;
}

Sample Calibration::to_sample(const imu::ImuRaw& raw) const {
  Sample s;
  s.accel = to_si(accel, raw.accel);
  s.gyro = to_si(gyro, raw.gyro);
  s.mag = to_si(mag, raw.mag);
  s.temperature_c = temperature_offset_c + temperature_scale * raw.temperature;
  s.has_mag = s.has_temperature = s.has_raw = true;
  auto it = s.raw.begin();
  for (const auto& axes : {raw.accel, raw.gyro, raw.mag}) it = std::copy(axes.begin(), axes.end(), it);
  *it = raw.temperature;
  return s;
}

imu::ImuRaw Calibration::to_counts(const std::array<double, 3>& accel_si, const std::array<double, 3>& gyro_si,
                                   const std::array<double, 3>& mag_si, double temperature_c) const {
  return {to_raw(accel, accel_si), to_raw(gyro, gyro_si), to_raw(mag, mag_si),
          to_count((temperature_c - temperature_offset_c) / temperature_scale)};
}

std::optional<Sample> to_sample(const imu::Frame& frame, const Calibration& calibration, const SourceKey& source,
                                std::int64_t recv_mono_ns) {
  const auto* raw = std::get_if<imu::ImuRaw>(&frame.payload);
  if (!raw) return std::nullopt;
  Sample s = calibration.to_sample(*raw);
  s.source = source;
  s.seq = frame.sequence;
  s.device_time_us = static_cast<std::int64_t>(frame.device_time_us);
  s.clock_epoch = frame.clock_epoch;
  s.recv_mono_ns = recv_mono_ns;
  return s;
}

}  // namespace imubridge::protocol
