#include "protocol/calibration.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

namespace imubridge::protocol {
namespace {

constexpr double kG = 9.80665;
constexpr double kDeg = std::numbers::pi / 180;

imu::ImuRaw counts(std::int16_t a, std::int16_t g, std::int16_t m, std::int16_t t) {
  return {{a, a, a}, {g, g, g}, {m, m, m}, t};
}

TEST(Calibration, ReferenceBoardDatasheetPoints) {
  const Calibration board = Calibration::reference_board();
  ASSERT_TRUE(board.valid());

  // ADXL327 at mid-supply is 0 g; 1 g is 420 mV, i.e. 0.42 / 3.3 * 4096 = 521.3 ADC counts, so the nearest whole
  // counts land within half a count (0.0094 m/s^2) of 1 g and -2 g; 4096 counts span 3.3 V = 3.3 / 0.42 g.
  EXPECT_DOUBLE_EQ(board.to_sample(counts(2048, 0, 0, 0)).accel[0], 0.0);
  EXPECT_NEAR(board.to_sample(counts(2048 + 521, 0, 0, 0)).accel[1], kG, 0.0094);
  EXPECT_NEAR(board.to_sample(counts(2048 - 1043, 0, 0, 0)).accel[2], -2 * kG, 0.0094);
  EXPECT_NEAR(board.to_sample(counts(2048 + 4096, 0, 0, 0)).accel[0], 3.3 / 0.42 * kG, 1e-9);
  // ITG3200: 2875 counts = 2875 / 14.375 = 200 deg/s.
  EXPECT_DOUBLE_EQ(board.to_sample(counts(2048, 2875, 0, 0)).gyro[0], 200 * kDeg);
  EXPECT_DOUBLE_EQ(board.to_sample(counts(2048, -115, 0, 0)).gyro[2], -8 * kDeg);
  // HMC5843: 1300 counts per gauss, so -650 counts = -0.5 gauss = -50 uT.
  EXPECT_DOUBLE_EQ(board.to_sample(counts(2048, 0, -650, 0)).mag[1], -50.0);
  // ITG3200 temperature: 35 C at -13200, 280 counts per degree.
  EXPECT_NEAR(board.to_sample(counts(2048, 0, 0, -13200)).temperature_c, 35.0, 1e-12);
  EXPECT_NEAR(board.to_sample(counts(2048, 0, 0, -16000)).temperature_c, 25.0, 1e-12);
}

TEST(Calibration, SampleCarriesRawCountsAndFlags) {
  const imu::ImuRaw raw{{1, 2, 3}, {4, 5, 6}, {7, 8, 9}, 10};
  const Sample s = Calibration::reference_board().to_sample(raw);
  EXPECT_EQ(s.raw, (std::array<std::int32_t, 10>{1, 2, 3, 4, 5, 6, 7, 8, 9, 10}));
  EXPECT_TRUE(s.has_raw);
  EXPECT_TRUE(s.has_mag);
  EXPECT_TRUE(s.has_temperature);
}

// A sensor mounted rotated and flipped: IMU x is sensor y, IMU y is minus sensor x, IMU z is minus sensor z.
AxisCalibration rotated_mount() {
  AxisCalibration c;
  c.scale = {1, 2, 3};
  c.offset = {10, 20, 30};
  c.source_axis = {1, 0, 2};
  c.sign = {1, -1, -1};
  return c;
}

TEST(Calibration, AxisMapWithSigns) {
  Calibration cal;
  cal.gyro = rotated_mount();
  const Sample s = cal.to_sample({{}, {100, 200, 300}, {}, 0});
  // Each output uses its source axis's scale and offset: 2 * (200 - 20), -(1 * (100 - 10)), -(3 * (300 - 30)).
  EXPECT_EQ(s.gyro, (std::array<double, 3>{360, -90, -810}));
}

TEST(Calibration, CountsSurviveARoundTrip) {
  Calibration cal = Calibration::reference_board();
  cal.accel = rotated_mount();
  std::mt19937 rng(1);
  std::uniform_int_distribution<int> count(-32768, 32767);
  for (int i = 0; i < 1000; ++i) {
    auto c = [&] { return static_cast<std::int16_t>(count(rng)); };
    const imu::ImuRaw raw{{c(), c(), c()}, {c(), c(), c()}, {c(), c(), c()}, c()};
    const Sample s = cal.to_sample(raw);
    ASSERT_EQ(cal.to_counts(s.accel, s.gyro, s.mag, s.temperature_c), raw);
  }
}

TEST(Calibration, SiValuesSurviveARoundTripWithinOneCount) {
  Calibration cal = Calibration::reference_board();
  cal.mag = rotated_mount();
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> unit(-1, 1);
  for (int i = 0; i < 1000; ++i) {
    const std::array<double, 3> accel{2 * kG * unit(rng), 2 * kG * unit(rng), 2 * kG * unit(rng)};
    const std::array<double, 3> gyro{5 * unit(rng), 5 * unit(rng), 5 * unit(rng)};
    const std::array<double, 3> mag{60 * unit(rng), 60 * unit(rng), 60 * unit(rng)};
    const double temperature = 30 + 40 * unit(rng);
    const Sample s = cal.to_sample(cal.to_counts(accel, gyro, mag, temperature));
    for (std::size_t k = 0; k < 3; ++k) {
      // Rounding to the nearest count moves a value by at most half of its axis's count.
      EXPECT_LE(std::abs(s.accel[k] - accel[k]), 0.5 * cal.accel.scale[k] + 1e-9);
      EXPECT_LE(std::abs(s.gyro[k] - gyro[k]), 0.5 * cal.gyro.scale[k] + 1e-9);
      EXPECT_LE(std::abs(s.mag[k] - mag[k]), 0.5 * cal.mag.scale[cal.mag.source_axis[k]] + 1e-9);
    }
    EXPECT_LE(std::abs(s.temperature_c - temperature), 0.5 * cal.temperature_scale + 1e-9);
  }
}

TEST(Calibration, CountsSaturate) {
  const Calibration board = Calibration::reference_board();
  const imu::ImuRaw high = board.to_counts({1e6, 1e6, 1e6}, {1e6, 1e6, 1e6}, {1e9, 1e9, 1e9}, 1e6);
  EXPECT_EQ(high, counts(32767, 32767, 32767, 32767));
  const imu::ImuRaw low = board.to_counts({-1e6, -1e6, -1e6}, {-1e6, -1e6, -1e6}, {-1e9, -1e9, -1e9}, -1e6);
  EXPECT_EQ(low, counts(-32768, -32768, -32768, -32768));
  const double inf = INFINITY, nan = NAN;
  EXPECT_EQ(board.to_counts({inf, -inf, nan}, {}, {}, nan), (imu::ImuRaw{{32767, -32768, 0}, {}, {}, 0}));
}

TEST(Calibration, ValidRejectsUnusableConfigurations) {
  EXPECT_TRUE(AxisCalibration{}.valid());
  EXPECT_TRUE(rotated_mount().valid());
  auto broken = [](auto mutate) {
    AxisCalibration c = rotated_mount();
    mutate(c);
    return c.valid();
  };
  EXPECT_FALSE(broken([](AxisCalibration& c) { c.source_axis = {0, 0, 2}; }));
  EXPECT_FALSE(broken([](AxisCalibration& c) { c.source_axis[2] = 3; }));
  EXPECT_FALSE(broken([](AxisCalibration& c) { c.sign[1] = 0; }));
  EXPECT_FALSE(broken([](AxisCalibration& c) { c.scale[0] = 0; }));
  EXPECT_FALSE(broken([](AxisCalibration& c) { c.scale[1] = NAN; }));
  EXPECT_FALSE(broken([](AxisCalibration& c) { c.offset[2] = INFINITY; }));
  Calibration cal;
  cal.temperature_scale = 0;
  EXPECT_FALSE(cal.valid());
}

TEST(Calibration, FrameToSample) {
  const imu::Frame frame{7, 65543, 123456, imu::ImuRaw{{2048, 2048, 2048}, {}, {}, -13200}};
  const auto s = to_sample(frame, Calibration::reference_board(), SourceKey{.link = 3}, 987654321);
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->source, (SourceKey{.link = 3}));
  EXPECT_EQ(s->seq, 65543u);  // the unwrapped sequence, not the wire's 16 bits
  EXPECT_EQ(s->device_time_us, 123456);
  EXPECT_EQ(s->recv_mono_ns, 987654321);
  EXPECT_NEAR(s->temperature_c, 35.0, 1e-12);

  const imu::Frame velocity{8, 8, 0, imu::VelocityEstimate{1, 2, 3, 4}};
  EXPECT_FALSE(to_sample(velocity, Calibration::reference_board(), SourceKey{.link = 3}, 0).has_value());
}

}  // namespace
}  // namespace imubridge::protocol
