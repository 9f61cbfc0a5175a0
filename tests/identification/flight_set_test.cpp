// Several flights joined into one series (identification/flight_set.hpp): where each lands, what is kept, and that the
// drag-velocity filter takes the gap between two flights as a pause, carrying nothing certain across it.
#include "identification/flight_set.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <stdexcept>
#include <vector>

#include "estimator/drag_velocity.hpp"

namespace imubridge::estimator {
namespace {

// A level hover at 100 Hz from `t0`, `n` samples, with or without a reference.
ImuSeries hover(double t0, std::size_t n, bool reference) {
  ImuSeries s;
  if (reference) s.reference.emplace();
  for (std::size_t i = 0; i < n; ++i) {
    s.t.push_back(t0 + 0.01 * static_cast<double>(i));
    s.gyro.push_back(Eigen::Vector3d::Zero());
    s.accel.push_back({0.0, 0.0, -9.80665});
    if (reference) {
      s.reference->velocity_ned.push_back(Eigen::Vector3d::Zero());
      s.reference->attitude.push_back(Eigen::Quaterniond::Identity());
    }
  }
  return s;
}

TEST(FlightSet, PlacesEachFlightAfterTheLastWithTheGapBetween) {
  const std::vector<ImuSeries> flights{hover(500.0, 1000, true), hover(3.0, 507, true)};
  const FlightSet set = join_flights(flights, 5);
  ASSERT_EQ(set.placed.size(), 2u);
  EXPECT_DOUBLE_EQ(set.placed[0].start, 0.0);
  EXPECT_NEAR(set.placed[0].end, 10.0, 1e-9);
  EXPECT_NEAR(set.placed[1].start, 10.0 + kFlightGapSeconds, 1e-9);
  // 507 samples keep 505: whole blocks of 5.
  EXPECT_EQ(set.series.size(), 1505u);
  EXPECT_NEAR(set.placed[1].end - set.placed[1].start, 5.05, 1e-9);
  EXPECT_NEAR(set.flown_seconds, 15.05, 1e-9);
  EXPECT_NEAR(set.shift[0], -500.0, 1e-9);
  EXPECT_TRUE(set.series.reference.has_value());
  EXPECT_FALSE(validate(set.series).has_value());
}

TEST(FlightSet, KeepsAReferenceOnlyWhenEveryFlightHasOne) {
  const std::vector<ImuSeries> flights{hover(0.0, 100, true), hover(0.0, 100, false)};
  EXPECT_FALSE(join_flights(flights).series.reference.has_value());
  EXPECT_THROW(join_flights(std::vector<ImuSeries>{}), std::invalid_argument);
  EXPECT_THROW(join_flights(std::vector<ImuSeries>{hover(0.0, 3, false)}, 5), std::invalid_argument);
}

TEST(FlightSet, CutKeepsTheWindowsSamplesAndTheirReference) {
  const ImuSeries s = cut(hover(0.0, 1000, true), {2.0, 3.0});
  ASSERT_EQ(s.size(), 100u);
  EXPECT_DOUBLE_EQ(s.t.front(), 2.0);
  ASSERT_TRUE(s.reference.has_value());
  EXPECT_EQ(s.reference->velocity_ned.size(), 100u);
}

TEST(FlightSet, TheFilterTakesTheGapBetweenFlightsAsAPause) {
  // The first flight cruises at 5 m/s (its drag reads -k v on x), the second hovers.
  constexpr double kDrag = 0.3;
  ImuSeries cruise = hover(0.0, 3000, false);
  for (Eigen::Vector3d& a : cruise.accel) a.x() = -kDrag * 5.0;
  const std::vector<ImuSeries> flights{cruise, hover(0.0, 1000, false)};
  const FlightSet set = join_flights(flights);
  FullModelParams params;
  params.drag_linear = {kDrag, kDrag};
  DragVelocityEstimator filter(params, DragVelocityConfig{});
  std::optional<DragVelocityEstimate> last_of_first, first_of_second;
  for (std::size_t k = 0; k < set.series.size(); ++k) {
    const auto e = filter.update(set.series.sample(k));
    if (!e) continue;
    if (e->t < set.placed[0].end) last_of_first = e;
    else if (!first_of_second) first_of_second = e;
  }
  ASSERT_TRUE(last_of_first && first_of_second);
  EXPECT_EQ(filter.counters().gaps, 1u);
  EXPECT_GT(last_of_first->v.x(), 4.0);
  // The second flight starts from its own drag, not from the first flight's speed.
  EXPECT_LT(std::abs(first_of_second->v.x()), 0.5);
}

}  // namespace
}  // namespace imubridge::estimator
