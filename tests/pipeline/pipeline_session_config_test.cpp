#include <gtest/gtest.h>

#include "pipeline/session_config.hpp"

namespace imubridge::pipeline {
namespace {

TEST(SessionConfig, LinksAndCalibrationsSurviveTheSnapshot) {
  protocol::Calibration odd = protocol::Calibration::reference_board();
  odd.accel.source_axis = {2, 0, 1};
  odd.accel.sign = {-1, 1, -1};
  odd.gyro.scale = {1e-4, 2e-4, 3e-4};
  odd.temperature_offset_c = -3.5;
  nlohmann::json config{{"other", 1}};
  add_recorded_links(config, {{"radio", protocol::WireFormat::xbee_escaped, odd},
                              {"fc", protocol::WireFormat::mavlink, protocol::Calibration::reference_board()}});
  const auto links = recorded_links(config.dump());
  ASSERT_EQ(links.size(), 2u);
  EXPECT_EQ(links[0].name, "radio");
  EXPECT_EQ(links[0].format, protocol::WireFormat::xbee_escaped);
  EXPECT_EQ(links[0].calibration, odd);  // doubles survive JSON exactly (shortest round trip)
  EXPECT_EQ(links[0].calibration.temperature_offset_c, -3.5);
  EXPECT_EQ(links[1].format, protocol::WireFormat::mavlink);
  EXPECT_EQ(links[1].mavlink_imu, std::nullopt);  // not written, read back as every IMU
}

TEST(SessionConfig, AMavlinkLinksImuSurvivesTheSnapshot) {
  const protocol::mavlink::ImuSource source{.msgid = 116, .sysid = 1, .compid = 200, .id = 0};
  nlohmann::json config;
  add_recorded_links(config, {{"telemetry", protocol::WireFormat::mavlink, protocol::Calibration{}, "frd", source}});
  EXPECT_EQ(config["links"][0]["mavlink_imu"]["message"], "SCALED_IMU2");
  const auto links = recorded_links(config.dump());
  ASSERT_EQ(links.size(), 1u);
  EXPECT_EQ(links[0].mavlink_imu, source);
  EXPECT_EQ(links[0].imu_axes, "frd");
}

TEST(SessionConfig, SnapshotsWithoutLinksOrWithBadCalibrationsAreRefused) {
  EXPECT_THROW(recorded_links("{}"), std::invalid_argument);
  EXPECT_THROW(recorded_links("not json"), std::invalid_argument);
  nlohmann::json config;
  add_recorded_links(config, {{"a", protocol::WireFormat::imubridge, protocol::Calibration::reference_board()}});
  config["links"][0]["calibration"]["accel"]["source_axis"] = {0, 0, 1};  // not a permutation
  EXPECT_THROW(recorded_links(config.dump()), std::invalid_argument);
  config["links"][0]["protocol"] = "ubx";
  EXPECT_THROW(recorded_links(config.dump()), std::invalid_argument);
}

}  // namespace
}  // namespace imubridge::pipeline
