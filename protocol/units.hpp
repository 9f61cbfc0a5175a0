#pragma once
// Unit conversions the protocols' measurements go through on their way to SI samples.

namespace imubridge::protocol {

inline constexpr double kStandardGravity = 9.80665;   // m/s^2 in one g, by definition
inline constexpr double kMicroteslaPerGauss = 100.0;  // 1 gauss = 1e-4 T

}  // namespace imubridge::protocol
