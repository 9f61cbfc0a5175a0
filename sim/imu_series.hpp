#pragma once
// A simulated flight as the estimator's input: what the IMU measured, with the simulator's truth as the reference
// a motion-capture system would give. Header-only, so the simulator library itself stays free of the estimator.
#include <span>

#include "estimator/imu_series.hpp"
#include "sim/simulator.hpp"

namespace imubridge::sim {

inline estimator::ImuSeries imu_series(std::span<const SimSample> samples) {
  estimator::ImuSeries series;
  series.reference.emplace();
  for (const SimSample& s : samples) {
    series.t.push_back(s.time_s);
    series.gyro.push_back(s.measured.gyro);
    series.accel.push_back(s.measured.accel);
    series.reference->velocity_ned.push_back(s.truth.velocity_ned);
    series.reference->attitude.push_back(s.truth.attitude);
  }
  return series;
}

}  // namespace imubridge::sim
