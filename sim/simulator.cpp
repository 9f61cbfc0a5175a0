#include "sim/simulator.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

namespace imubridge::sim {

namespace {

constexpr std::uint64_t kNoiseStream = 2;  // the flight plan draws from stream 1

std::array<double, 3> array_of(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }
Eigen::Vector3d vector_of(const std::array<double, 3>& a) { return {a[0], a[1], a[2]}; }

// The rates and the duration decide how many steps and samples exist; anything else is a physical parameter.
const SimConfig& checked(const SimConfig& config) {
  const bool ok = std::isfinite(config.duration_s) && config.duration_s >= 0 && std::isfinite(config.imu.rate_hz) &&
                  config.imu.rate_hz > 0 && std::isfinite(config.flight.physics_rate_hz) &&
                  config.flight.physics_rate_hz > 0 && std::isfinite(config.imu.errors.time_offset_s);
  if (!ok) throw std::invalid_argument("SimConfig: rates must be positive, the duration non-negative, all finite");
  return config;
}

}  // namespace

Simulator::Simulator(const SimConfig& config)
    : config_(checked(config)),
      flight_(config.flight, config.duration_s, config.seed),
      errors_(config.imu.errors, config.imu.rate_hz, Rng::stream(config.seed, kNoiseStream)),
      sample_count_(static_cast<std::uint64_t>(std::llround(config.duration_s * config.imu.rate_hz))) {}

std::optional<SimSample> Simulator::next() {
  if (next_index_ >= sample_count_) return std::nullopt;
  SimSample s;
  s.index = next_index_++;
  s.time_s = static_cast<double>(s.index) / config_.imu.rate_hz;
  s.truth = flight_.at(s.time_s);
  s.ideal = ideal_reading(config_.imu, s.truth);
  const double lag = config_.imu.errors.time_offset_s;
  const Eigen::Vector3d lagged_accel =
      lag == 0.0 ? s.ideal.accel : ideal_reading(config_.imu, flight_.at(s.time_s - lag)).accel;
  const ImuReading analog = errors_.apply(s.ideal, lagged_accel, s.time_s);
  const protocol::Calibration& calibration = config_.imu.calibration;
  s.raw =
      calibration.to_counts(array_of(analog.accel), array_of(analog.gyro), array_of(analog.mag), analog.temperature_c);
  const protocol::Sample decoded = calibration.to_sample(s.raw);
  s.measured = {vector_of(decoded.accel), vector_of(decoded.gyro), vector_of(decoded.mag), decoded.temperature_c};
  flight_.forget_before(std::min(s.time_s, s.time_s - lag));
  return s;
}

void simulate(const SimConfig& config, const std::function<void(const SimSample&)>& sink) {
  Simulator sim(config);
  while (auto sample = sim.next()) sink(*sample);
}

std::vector<SimSample> simulate(const SimConfig& config) {
  std::vector<SimSample> samples;
  simulate(config, [&](const SimSample& s) { samples.push_back(s); });
  return samples;
}

}  // namespace imubridge::sim
