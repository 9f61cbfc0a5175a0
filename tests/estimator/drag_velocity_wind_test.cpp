// Why `diagnose` does not find a constant wind from the IMU alone, even on a flight that turns its heading
// (docs/effects.md, "The wind from the IMU alone"): the drag-velocity filter that the filter error method fits by
// predicts the accelerometer as well without the wind as with it, its own velocity standing in for the wind. Turns
// rotate the wind through the body axes, but the filter's velocity turns with them (its -w x v term). If this test
// fails, the filter has learnt to tell a wind from a ground velocity, and the docs' finding needs measuring again.
#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <vector>

#include "estimator/drag_velocity.hpp"
#include "sim/scenario.hpp"
#include "sim/simulator.hpp"

namespace imubridge {
namespace {

struct FilterRun {
  double innovation_rms = 0.0;         // m/s^2, both horizontal axes, after the settling time
  double ground_velocity_error = 0.0;  // RMS of the filtered velocity against the true ground velocity, m/s
  double air_velocity_error = 0.0;     // ... against the true air velocity, m/s
};

constexpr double kSettleS = 5.0;

FilterRun run_filter(const std::vector<sim::SimSample>& flight, const Eigen::Vector2d& wind, double mu) {
  estimator::FullModelParams params;  // the IMU at the mass centre, axes aligned, as the flight below has it
  params.drag_quadratic = {mu, mu};
  params.wind = wind;  // north, east; the flight starts with its nose north, as the filter's heading does
  estimator::DragVelocityEstimator filter(params, estimator::DragVelocityConfig{});
  const double rate = 1.0 / (flight[1].time_s - flight[0].time_s);
  double innovation = 0.0, ground = 0.0, air = 0.0;
  std::size_t n = 0;
  for (const sim::SimSample& s : flight) {
    const std::optional<estimator::DragVelocityEstimate> e =
        filter.update({s.time_s, s.measured.gyro, s.measured.accel});
    if (!e || e->t < kSettleS) continue;
    // The estimate belongs to the sample delay_samples() back.
    const auto k = static_cast<std::size_t>(std::lround(e->t * rate));
    const sim::TrueState& truth = flight[k].truth;
    innovation += e->innovation.squaredNorm();
    ground += (e->v - truth.velocity_body.head<2>()).squaredNorm();
    air += (e->v - truth.air_velocity_body.head<2>()).squaredNorm();
    ++n;
  }
  const double count = static_cast<double>(n);
  return {std::sqrt(innovation / (2 * count)), std::sqrt(ground / (2 * count)), std::sqrt(air / (2 * count))};
}

TEST(WindFromTheImuAlone, OnATurningFlightAWindPredictsNoBetterThanASteadyGroundVelocity) {
  sim::SimConfig config = sim::make_scenario("survey", 41, 30.0, std::vector<std::string>{"wind=5,0"});
  config.imu.pose = sim::ImuPose{};  // at the mass centre: the filter needs no lever arm or mounting
  const std::vector<sim::SimSample> flight = sim::simulate(config);
  const double mu = config.flight.air.quadratic_drag_per_m;

  const FilterRun with_wind = run_filter(flight, {5.0, 0.0}, mu);
  const FilterRun without = run_filter(flight, Eigen::Vector2d::Zero(), mu);

  // The model with the wind is the true one: its velocity is the ground velocity.
  EXPECT_LT(with_wind.ground_velocity_error, 0.5);
  // Without the wind, the filter's velocity is the air velocity: it reads the wind as the vehicle moving at 5 m/s.
  EXPECT_LT(without.air_velocity_error, 0.5);
  EXPECT_GT(without.ground_velocity_error, 3.0);
  // And the accelerometer is predicted as well either way: what the filter error method fits by cannot tell them
  // apart (within a tenth).
  EXPECT_NEAR(without.innovation_rms / with_wind.innovation_rms, 1.0, 0.1)
      << "innovation RMS with the wind " << with_wind.innovation_rms << ", without " << without.innovation_rms;
}

}  // namespace
}  // namespace imubridge
