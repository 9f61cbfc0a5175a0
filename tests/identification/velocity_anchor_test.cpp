// The least-squares anchor (identification/velocity_scores.hpp): a = -k v + b on 0.1-s means, inverted raw and 1-s
// smoothed, on its own flight and carried to another.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <stdexcept>

#include "identification/velocity_scores.hpp"

namespace imubridge::estimator {
namespace {

// A level flight at 200 Hz (identity attitude: body = NED), velocity v(t) = (3 sin(0.2 t), 2 cos(0.15 t)), whose
// accelerometer reads -k v + b plus white vibration of `vibration` m/s^2 RMS per axis.
ImuSeries drag_flight(const Eigen::Vector2d& k, const Eigen::Vector2d& b, double vibration, unsigned seed,
                      double seconds = 60.0) {
  std::mt19937 random(seed);
  std::normal_distribution<double> noise(0.0, vibration);
  ImuSeries s;
  s.reference.emplace();
  for (int i = 0; i < static_cast<int>(seconds * 200.0); ++i) {
    const double t = i / 200.0;
    const Eigen::Vector2d v(3.0 * std::sin(0.2 * t), 2.0 * std::cos(0.15 * t));
    const Eigen::Vector2d a = -k.cwiseProduct(v) + b;
    s.t.push_back(t);
    s.gyro.push_back(Eigen::Vector3d::Zero());
    s.accel.push_back({a.x() + noise(random), a.y() + noise(random), -9.80665});
    s.reference->velocity_ned.push_back({v.x(), v.y(), 0.0});
    s.reference->attitude.push_back(Eigen::Quaterniond::Identity());
  }
  return s;
}

TEST(LeastSquaresAnchor, FitsTheDragLineOnBlockMeans) {
  const ImuSeries s = drag_flight({0.3, 0.2}, {-0.5, 0.4}, 2.0, 1);
  const LeastSquaresDrag fit = fit_least_squares_drag(s, {0.0, 60.0});
  EXPECT_NEAR(fit.k.x(), 0.3, 0.02);
  EXPECT_NEAR(fit.k.y(), 0.2, 0.02);
  EXPECT_NEAR(fit.b.x(), -0.5, 0.05);
  EXPECT_NEAR(fit.b.y(), 0.4, 0.05);
}

TEST(LeastSquaresAnchor, SmoothingTakesTheVibrationOutOfTheInvertedVelocity) {
  const ImuSeries s = drag_flight({0.3, 0.3}, {0.0, 0.0}, 2.0, 2);
  const LeastSquaresDragScores scores = score_least_squares_drag(s, {{0.3, 0.3}, {0.0, 0.0}, ""}, {0.0, 60.0});
  EXPECT_EQ(scores.blocks, 600u);
  // 2 m/s^2 of white vibration over a 0.1-s block of 20 samples leaves 0.45 m/s^2, 1.5 m/s once divided by k; the
  // 1-s average of 10 blocks a third of that.
  EXPECT_NEAR(scores.raw.axis.x(), 2.0 / std::sqrt(20.0) / 0.3, 0.2);
  EXPECT_NEAR(scores.smoothed.axis.x(), 2.0 / std::sqrt(200.0) / 0.3, 0.12);
}

TEST(LeastSquaresAnchor, CarriedToAnotherFlightItCarriesTheFirstFlightsOffset) {
  const ImuSeries calibration = drag_flight({0.3, 0.3}, {0.0, 0.0}, 0.5, 3);
  const ImuSeries restrapped = drag_flight({0.3, 0.3}, {0.6, 0.0}, 0.5, 4);  // 3.5 degrees of pitch: 0.6 m/s^2
  const LeastSquaresDrag fit = fit_least_squares_drag(calibration, {0.0, 60.0});
  const LeastSquaresDragScores own = score_least_squares_drag(calibration, fit, {0.0, 60.0});
  const LeastSquaresDragScores carried = score_least_squares_drag(restrapped, fit, {0.0, 60.0});
  EXPECT_LT(own.smoothed.axis.x(), 0.3);
  EXPECT_NEAR(carried.smoothed.axis.x(), 0.6 / 0.3, 0.3);  // the offset over the drag: 2 m/s on x
  EXPECT_LT(carried.smoothed.axis.y(), 0.3);
}

TEST(LeastSquaresAnchor, RefusesWhatItCannotFit) {
  ImuSeries s = drag_flight({0.3, 0.3}, {0.0, 0.0}, 0.1, 5);
  EXPECT_THROW(fit_least_squares_drag(s, {100.0, 200.0}), std::invalid_argument);  // no block in the window
  EXPECT_THROW(score_least_squares_drag(s, {{0.3, 0.3}, {0.0, 0.0}, ""}, {100.0, 200.0}), std::invalid_argument);
  // An accelerometer that rises with the velocity is no drag: nothing to invert.
  for (std::size_t i = 0; i < s.size(); ++i) s.accel[i].x() = -s.accel[i].x();
  try {
    fit_least_squares_drag(s, {0.0, 60.0});
    FAIL() << "a rising line was inverted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("x velocity"), std::string::npos) << e.what();
  }
  s.reference.reset();
  EXPECT_THROW(fit_least_squares_drag(s, {0.0, 60.0}), std::invalid_argument);
}

// An axis whose accelerometer does not fall with the velocity beyond its noise has no drag to invert: the anchor
// flies it at zero velocity, as a user would, and says so, instead of dividing by a slope that is noise (the X500's y
// gave 11 m/s that way).
TEST(LeastSquaresAnchor, AnAxisWithoutADragReadFliesAtZeroVelocity) {
  const ImuSeries s = drag_flight({0.3, 0.0}, {0.0, 0.2}, 1.0, 6);  // y: no drag, the vibration alone
  const LeastSquaresDrag fit = fit_least_squares_drag(s, {0.0, 60.0});
  EXPECT_NEAR(fit.k.x(), 0.3, 0.03);
  EXPECT_EQ(fit.k.y(), 0.0);
  EXPECT_NE(fit.note.find("no drag read on y"), std::string::npos) << fit.note;
  const LeastSquaresDragScores scores = score_least_squares_drag(s, fit, {0.0, 60.0});
  // y's error is then the reference's own y speed, not a velocity divided out of noise.
  double vy2 = 0.0;
  for (const Eigen::Vector3d& v : s.reference->velocity_ned) vy2 += v.y() * v.y();
  EXPECT_NEAR(scores.smoothed.axis.y(), std::sqrt(vy2 / static_cast<double>(s.size())), 0.05);
}

}  // namespace
}  // namespace imubridge::estimator
