// Velocity feedback to the vehicle: rate limiting on the estimate clock, and frames that the protocol decoders read
// back to the estimate's velocity.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>

#include "daemon/vehicle_feedback.hpp"
#include "protocol/imu_frame.hpp"
#include "protocol/xbee.hpp"

namespace imubridge::daemon {
namespace {

using protocol::WireFormat;

constexpr std::int64_t kT0 = 7'000'000'000;  // any monotonic time

store::Estimate estimate(double vx = 1.25, double vy = -0.5) {
  return {.seq = 9, .t_s = 12.345678, .vx = vx, .vy = vy, .var_vx = 0.04, .var_vy = 0.0025};
}

VehicleFeedbackConfig enabled(double rate_hz = 10.0) { return {.enabled = true, .rate_hz = rate_hz}; }

std::vector<protocol::imu::Frame> decode_imu(std::span<const std::uint8_t> bytes) {
  protocol::imu::Decoder decoder;
  std::vector<protocol::imu::Frame> frames;
  decoder.feed(bytes, frames);
  decoder.finish(frames);
  EXPECT_EQ(decoder.counters().bytes_discarded, 0u);
  return frames;
}

void expect_velocity_of(const protocol::imu::Frame& frame, const store::Estimate& e) {
  ASSERT_EQ(frame.type(), protocol::imu::MsgType::velocity_estimate);
  const auto& v = std::get<protocol::imu::VelocityEstimate>(frame.payload);
  EXPECT_EQ(v.vx, static_cast<float>(e.vx));
  EXPECT_EQ(v.vy, static_cast<float>(e.vy));
  EXPECT_EQ(v.sigma_vx, static_cast<float>(std::sqrt(e.var_vx)));
  EXPECT_EQ(v.sigma_vy, static_cast<float>(std::sqrt(e.var_vy)));
  EXPECT_EQ(frame.device_time_us, 12'345'678u);  // the described sample's device time
}

TEST(VehicleFeedback, RateLimitIsExactOnTheEstimateClock) {
  VehicleFeedback feedback(WireFormat::imubridge, enabled(10.0));  // at most one per 100 000 000 ns
  EXPECT_TRUE(feedback.on_estimate(estimate(), kT0));
  EXPECT_FALSE(feedback.on_estimate(estimate(), kT0 + 99'999'999));
  EXPECT_TRUE(feedback.on_estimate(estimate(), kT0 + 100'000'000));
  EXPECT_FALSE(feedback.on_estimate(estimate(), kT0 + 150'000'000));
  EXPECT_TRUE(feedback.on_estimate(estimate(), kT0 + 200'000'000));  // measured from the last one sent

  VehicleFeedback third(WireFormat::imubridge, enabled(3.0));  // 1e9 / 3 rounds to 333 333 333 ns
  EXPECT_TRUE(third.on_estimate(estimate(), kT0));
  EXPECT_FALSE(third.on_estimate(estimate(), kT0 + 333'333'332));
  EXPECT_TRUE(third.on_estimate(estimate(), kT0 + 333'333'333));
  EXPECT_EQ(third.counters(), (nlohmann::json{{"sent", 2}, {"rate_limited", 1}, {"not_finite", 0}}));
}

TEST(VehicleFeedback, EstimatesAt100HzBecomeEveryTenthAt10Hz) {
  VehicleFeedback feedback(WireFormat::imubridge, enabled(10.0));
  std::vector<int> sent;
  for (int i = 0; i < 100; ++i) {
    if (feedback.on_estimate(estimate(), kT0 + i * 10'000'000)) sent.push_back(i);
  }
  EXPECT_EQ(sent, (std::vector<int>{0, 10, 20, 30, 40, 50, 60, 70, 80, 90}));
}

TEST(VehicleFeedback, ImubridgeLinksGetNumberedVelocityFrames) {
  VehicleFeedback feedback(WireFormat::imubridge, enabled(10.0));
  std::vector<std::uint8_t> stream;
  for (int i = 0; i < 3; ++i) {
    const auto bytes = feedback.on_estimate(estimate(0.5 * i, -0.25 * i), kT0 + i * 100'000'000);
    ASSERT_TRUE(bytes);
    stream.insert(stream.end(), bytes->begin(), bytes->end());
  }
  const auto frames = decode_imu(stream);
  ASSERT_EQ(frames.size(), 3u);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(frames[i].seq, i);
    expect_velocity_of(frames[i], estimate(0.5 * i, -0.25 * i));
  }
}

class XbeeFeedback : public ::testing::TestWithParam<WireFormat> {};

TEST_P(XbeeFeedback, TxRequestToTheVehicleRadioCarriesTheFrame) {
  const auto mode =
      GetParam() == WireFormat::xbee ? protocol::xbee::ApiMode::unescaped : protocol::xbee::ApiMode::escaped;
  VehicleFeedbackConfig config = enabled();
  config.xbee_destination64 = 0x0013A20040A1B2C3;  // its 0x13 must be escaped in API mode 2
  VehicleFeedback feedback(GetParam(), config);
  const auto bytes = feedback.on_estimate(estimate(), kT0);
  ASSERT_TRUE(bytes);

  protocol::xbee::Decoder decoder(mode);
  std::vector<protocol::xbee::Frame> frames;
  decoder.feed(*bytes, frames);
  decoder.finish(frames);
  ASSERT_EQ(frames.size(), 1u);
  EXPECT_EQ(decoder.counters().bytes_discarded, 0u);
  EXPECT_EQ(frames[0].frame_type, protocol::xbee::kTxRequest);
  const auto& tx = std::get<protocol::xbee::TxRequest>(frames[0].body);
  EXPECT_EQ(tx.destination64, 0x0013A20040A1B2C3u);
  EXPECT_EQ(tx.destination16, 0xFFFE);
  EXPECT_EQ(tx.frame_id, 0);  // no TX status frames back
  const auto inner = decode_imu(tx.payload);
  ASSERT_EQ(inner.size(), 1u);
  expect_velocity_of(inner[0], estimate());
}

INSTANTIATE_TEST_SUITE_P(BothApiModes, XbeeFeedback, ::testing::Values(WireFormat::xbee, WireFormat::xbee_escaped),
                         [](const auto& info) { return info.param == WireFormat::xbee ? "mode1" : "mode2"; });

TEST(VehicleFeedback, NonFiniteEstimatesSendNothingAndKeepTheSlot) {
  constexpr double nan = std::numeric_limits<double>::quiet_NaN();
  VehicleFeedback feedback(WireFormat::imubridge, enabled(10.0));
  EXPECT_FALSE(feedback.on_estimate(estimate(nan, 0.0), kT0));
  EXPECT_FALSE(feedback.on_estimate(estimate(0.0, nan), kT0));
  store::Estimate no_variance = estimate();
  no_variance.var_vy = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(feedback.on_estimate(no_variance, kT0));
  const auto bytes = feedback.on_estimate(estimate(), kT0);  // the first usable one goes out at once
  ASSERT_TRUE(bytes);
  EXPECT_EQ(decode_imu(*bytes).at(0).seq, 0);  // nothing above used up a sequence number
  EXPECT_EQ(feedback.counters(), (nlohmann::json{{"sent", 1}, {"rate_limited", 0}, {"not_finite", 3}}));
}

TEST(VehicleFeedback, DisabledSendsNothing) {
  VehicleFeedback feedback(WireFormat::imubridge, VehicleFeedbackConfig{});
  EXPECT_FALSE(feedback.on_estimate(estimate(), kT0));
  VehicleFeedback mavlink(WireFormat::mavlink, VehicleFeedbackConfig{});  // disabled: fine on any link
  EXPECT_FALSE(mavlink.on_estimate(estimate(), kT0));
}

TEST(VehicleFeedback, RefusesMavlinkAndBadRates) {
  EXPECT_THROW(VehicleFeedback(WireFormat::mavlink, enabled()), std::invalid_argument);
  for (double rate : {0.0, -1.0, std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    EXPECT_THROW(VehicleFeedback(WireFormat::imubridge, enabled(rate)), std::invalid_argument) << rate;
  }
}

}  // namespace
}  // namespace imubridge::daemon
