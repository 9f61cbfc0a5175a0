// The accelerometer offset a calibration carries to flights it was not fitted on, measured on flights that validate
// it (estimator::measure_transfer_offset): what makes the live filter's variance honest there, kept in PARAMS.json.
#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "estimator/drag_velocity.hpp"
#include "estimator/params.hpp"
#include "identification/identify.hpp"
#include "identification/velocity_scores.hpp"
#include "sim/imu_series.hpp"
#include "sim/scenario.hpp"
#include "sim/simulator.hpp"

namespace imubridge::estimator {
namespace {

ImuSeries paper_flight(unsigned seed, std::vector<std::string> effects = {}) {
  return sim::imu_series(sim::simulate(sim::make_scenario("paper", seed, 50.0, effects)));
}

ModelParams calibration() {
  IdentifyOptions o;
  o.model = ModelKind::full;
  o.velocity = VelocitySource::reference;
  o.train = TimeWindow{0.0, 30.0};
  o.validate = TimeWindow{30.0, 50.0};
  o.hold.blocks[static_cast<std::size_t>(FullBlock::accel_bias)] = true;
  return identify(paper_flight(1), o).params;
}

TEST(TransferOffset, GrowsWithTheOffsetsTheValidatingFlightsCarry) {
  const ModelParams params = calibration();
  const std::vector<TimeWindow> windows(2, TimeWindow{5.0, 50.0});
  const std::vector<ImuSeries> alike{paper_flight(4), paper_flight(5)};
  // Offsets of 1.5 m/s^2, beyond the datasheet default the filter counts without a measurement (0.59 m/s^2).
  const std::vector<ImuSeries> restrapped{paper_flight(4, {"accel_bias=1.2,-0.9,0"}),
                                          paper_flight(5, {"accel_bias=-1.2,0.9,0"})};
  const TransferOffset same = measure_transfer_offset(alike, windows, params);
  const TransferOffset moved = measure_transfer_offset(restrapped, windows, params);
  EXPECT_EQ(moved.flights, 2u);
  EXPECT_GT(moved.offset_std, same.offset_std + 0.15);
  EXPECT_GT(moved.nees_default, 2.0);
  ASSERT_FALSE(moved.at_limit);
  EXPECT_NEAR(moved.nees, 2.0, 0.1);  // honest with the measured offset
}

TEST(TransferOffset, TheLiveFilterCountsTheMeasuredOffsetOnAnotherFlightOnly) {
  ModelParams params;
  params.full.drag_linear = {0.3, 0.3};
  params.identification.transfer_offset_std = 0.8;
  EXPECT_EQ(config_for(params).accel_offset_std, 0.0);  // the flight it was fitted on
  params.transferred = true;
  EXPECT_EQ(config_for(params).accel_offset_std, 0.8);
  EXPECT_EQ(config_for(params).wind_std, 0.0);  // the measured offset is all a new flight carries, wind included
  params.identification.transfer_offset_std.reset();
  EXPECT_EQ(config_for(params).accel_offset_std, kTransferredOffsetStd);
  EXPECT_EQ(config_for(params).wind_std, kTransferredWindStd);  // nothing measured: two flights' winds differ
  params.transferred = false;
  EXPECT_EQ(config_for(params).wind_std, 0.0);  // its own flight's wind went into the fit
}

TEST(TransferOffset, AFitFromTheImuAloneDidNotPlaceTheOffsetEvenOnItsOwnFlight) {
  ModelParams params;
  params.full.drag_linear = {0.3, 0.3};
  EXPECT_EQ(config_for(params).accel_offset_std, 0.0);  // fitted against a reference: the fit placed the offset
  params.identification.process_noise = 0.8;            // the filter error method: fitted from the IMU alone
  EXPECT_EQ(config_for(params).accel_offset_std, kTransferredOffsetStd);
  EXPECT_EQ(config_for(params).wind_std, 0.0);  // the flight's own wind is in what the drag reads, as in the fit
}

// diagnose judges a step on a flight set by its validating flights: other flights, which the calibration flies as
// any new one (transferred: their offset unknown, weighed towards rest), not as the flight it was fitted on.
TEST(TransferOffset, AFlightSetsValidatingFlightsAreScoredAsTheCalibrationFliesThere) {
  ModelParams params = calibration();
  params.full.accel_bias = {0.3, -0.2, 0.0};  // a condition of the fitting flights, which stays with them
  const ImuSeries other = paper_flight(4, {"accel_bias=0.4,-0.3,0"});
  const Windows windows{TimeWindow{5.0, 25.0}, TimeWindow{25.0, 50.0}};
  ModelParams elsewhere = params;
  elsewhere.full.accel_bias.setZero();
  elsewhere.transferred = true;
  const double flown =
      evaluate_velocity(other, elsewhere.full, windows.validate, config_for(elsewhere)).estimator.horizontal;
  const double as_fitted =
      evaluate_velocity(other, params.full, windows.validate, config_for(params)).estimator.horizontal;
  ASSERT_GT(std::abs(flown - as_fitted), 1e-3);  // the two differ on this flight: the test can tell them apart

  const std::optional<VelocityScores> set = score_velocity(other, params, windows, true);
  const std::optional<VelocityScores> own = score_velocity(other, params, windows, false);
  ASSERT_TRUE(set && own);
  EXPECT_DOUBLE_EQ(set->validation.horizontal, flown);
  EXPECT_DOUBLE_EQ(own->validation.horizontal, as_fitted);
  EXPECT_DOUBLE_EQ(set->train.horizontal, own->train.horizontal);  // the fitting flights are the calibration's own
}

TEST(TransferOffset, RefusesFlightsItCannotScore) {
  const ModelParams params = calibration();
  ImuSeries without = paper_flight(4);
  without.reference.reset();
  const std::vector<TimeWindow> window{TimeWindow{5.0, 50.0}};
  EXPECT_THROW(measure_transfer_offset(std::vector<ImuSeries>{without}, window, params), std::invalid_argument);
  EXPECT_THROW(measure_transfer_offset(std::vector<ImuSeries>{}, {}, params), std::invalid_argument);
}

}  // namespace
}  // namespace imubridge::estimator
