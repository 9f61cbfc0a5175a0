// The flight found from the IMU alone: a recording that rests, flies with the rotors' vibration and rests again gives
// the flying part; one without a quiet part gives none; and how much of a window lies in the flight.
#include "identification/flight_span.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace imubridge::estimator {
namespace {

constexpr double kRate = 200.0;  // Hz

// `rest` s on the ground (sensor noise only), `fly` s with vibration, `rest` s on the ground again. Seeded.
ImuSeries rest_fly_rest(double rest, double fly, double vibration) {
  ImuSeries s;
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 0.01);
  const int n = static_cast<int>((2 * rest + fly) * kRate);
  for (int i = 0; i < n; ++i) {
    const double t = i / kRate;
    const bool flying = t >= rest && t < rest + fly;
    // Rotor vibration: a 90 Hz tone on every axis, well inside the band a sample-to-sample change sees.
    const double shake = flying ? vibration * std::sin(2 * M_PI * 90.0 * t) : 0.0;
    s.t.push_back(t);
    s.gyro.emplace_back(noise(rng) * 0.1, noise(rng) * 0.1, noise(rng) * 0.1);
    s.accel.emplace_back(shake + noise(rng), shake + noise(rng), -9.81 + shake + noise(rng));
  }
  return s;
}

TEST(FlightSpan, TheFlyingPartOfARecordingThatRestsBeforeAndAfter) {
  const auto flight = detect_flight(rest_fly_rest(5.0, 20.0, 1.0));
  ASSERT_TRUE(flight);
  EXPECT_NEAR(flight->window.start, 5.0, kFlightBlockSeconds);
  EXPECT_NEAR(flight->window.end, 25.0, kFlightBlockSeconds);
  EXPECT_GT(flight->flying_level, kMinFlightContrast * flight->quiet_level);
  EXPECT_FALSE(flight->description.empty());
}

TEST(FlightSpan, NoneWithoutAQuietPartToTellItFrom) {
  EXPECT_FALSE(detect_flight(rest_fly_rest(0.0, 20.0, 1.0)));  // airborne throughout
  EXPECT_FALSE(detect_flight(rest_fly_rest(10.0, 0.0, 1.0)));  // on the ground throughout
  EXPECT_FALSE(detect_flight(rest_fly_rest(0.2, 0.3, 1.0)));   // shorter than two blocks
}

TEST(FlightSpan, TheShareOfAWindowInTheFlight) {
  const TimeWindow flight{2.0, 6.0}, data{0.0, 69.0};
  EXPECT_DOUBLE_EQ(*share_in_flight({0.0, 33.0}, flight, data), 4.0 / 33.0);  // the default fit window, seconds
  EXPECT_DOUBLE_EQ(*share_in_flight({2.0, 3.6}, flight, data), 1.0);          // 0:40% of the flight
  EXPECT_DOUBLE_EQ(*share_in_flight({33.0, 1e9}, flight, data), 0.0);         // clipped to the data: 33 to 69 s
  EXPECT_DOUBLE_EQ(*share_in_flight({5.0, 10.0}, flight, data), 0.2);
  EXPECT_FALSE(share_in_flight({80.0, 90.0}, flight, data));  // beyond the data: empty
}

}  // namespace
}  // namespace imubridge::estimator
