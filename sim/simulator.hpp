#pragma once
// The simulator: a flight sampled by an IMU. Fully determined by its SimConfig (scenario.hpp builds one from a
// scenario name, seed, duration and effects): the same config gives bit-identical samples.
#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

#include "protocol/imu_frame.hpp"
#include "sim/flight.hpp"
#include "sim/imu_model.hpp"
#include "sim/reference.hpp"

namespace imubridge::sim {

struct SimConfig {
  FlightConfig flight;
  ImuConfig imu;
  ReferenceConfig reference;  // what a recording takes as its reference trajectory (sim/reference.hpp)
  double duration_s = 60.0;
  std::uint64_t seed = 0;
};

struct SimSample {
  std::uint64_t index = 0;  // sample n is taken at t = n / imu.rate_hz
  double time_s = 0.0;
  TrueState truth;
  ImuReading ideal;     // a perfect sensor at the IMU's pose
  ImuReading measured;  // with every sensor error, quantised: what the ground station decodes from `raw`
  protocol::imu::ImuRaw raw;
};

class Simulator {
 public:
  // Throws std::invalid_argument for a non-positive or non-finite rate, or a negative or non-finite duration.
  explicit Simulator(const SimConfig& config);

  // The next sample, or nothing once the flight's duration is covered. Memory stays bounded however long it runs.
  std::optional<SimSample> next();
  std::uint64_t sample_count() const { return sample_count_; }
  const Flight& flight() const { return flight_; }

 private:
  SimConfig config_;
  Flight flight_;
  ImuErrorModel errors_;
  std::uint64_t sample_count_;
  std::uint64_t next_index_ = 0;
};

// Streams every sample to `sink`.
void simulate(const SimConfig& config, const std::function<void(const SimSample&)>& sink);
// Every sample at once, for short flights.
std::vector<SimSample> simulate(const SimConfig& config);

}  // namespace imubridge::sim
