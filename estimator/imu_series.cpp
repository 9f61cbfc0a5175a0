#include "estimator/imu_series.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <stdexcept>

namespace imubridge::estimator {

std::optional<std::string> validate(const ImuSeries& s) {
  const std::size_t n = s.t.size();
  if (s.gyro.size() != n || s.accel.size() != n) return "gyro/accel length differs from t";
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(s.t[i]) || !s.gyro[i].allFinite() || !s.accel[i].allFinite())
      return "non-finite value at sample " + std::to_string(i);
    if (i > 0 && !(s.t[i] > s.t[i - 1])) return "time not strictly increasing at sample " + std::to_string(i);
  }
  if (s.reference) {
    const ReferenceSeries& r = *s.reference;
    if (r.velocity_ned.size() != n || r.attitude.size() != n) return "reference length differs from t";
    for (std::size_t i = 0; i < n; ++i) {
      // 1e-6 admits quaternions stored as floats; anything further off is not a rotation.
      if (!r.velocity_ned[i].allFinite() || !r.attitude[i].coeffs().allFinite() ||
          std::abs(r.attitude[i].norm() - 1.0) > 1e-6)
        return "invalid reference at sample " + std::to_string(i);
    }
  }
  return std::nullopt;
}

void require_valid(const ImuSeries& series) {
  if (auto error = validate(series)) throw std::invalid_argument("ImuSeries: " + *error);
}

std::string flight_identity(const ImuSeries& series) {
  // FNV-1a over the bytes of the first samples: enough to tell flights apart, the same wherever they are read.
  constexpr std::size_t kSamples = 512;
  std::uint64_t hash = 14695981039346656037ull;
  const auto mix = [&](double value) {
    unsigned char bytes[sizeof value];
    std::memcpy(bytes, &value, sizeof value);
    for (unsigned char b : bytes) hash = (hash ^ b) * 1099511628211ull;
  };
  for (std::size_t k = 0; k < std::min(series.size(), kSamples); ++k) {
    mix(series.t[k]);
    for (int i = 0; i < 3; ++i) mix(series.gyro[k][i]), mix(series.accel[k][i]);
  }
  char text[24];
  std::snprintf(text, sizeof text, "imu:%016llx", static_cast<unsigned long long>(hash));
  return text;
}

}  // namespace imubridge::estimator
