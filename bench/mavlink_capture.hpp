#pragma once
// The synthetic MAVLink capture both MAVLink benchmarks decode (mavlink_decode_bench against the CRC pass,
// mavlink_c_library_bench against the MAVLink C library), so that their figures are about the same bytes.
#include <cstddef>
#include <cstdint>
#include <random>
#include <vector>

#include "protocol/mavlink.hpp"

namespace imubridge::bench {

struct MavlinkCapture {
  std::vector<std::uint8_t> bytes;
  std::size_t frames = 0;  // frames written, each a valid frame a decoder should find
};

// About `size` bytes of what a PX4 sends when asked for IMU data: MAVLink 2 HIGHRES_IMU frames at the IMU rate with an
// ATTITUDE every fourth, plausible values. With garbage, random bytes (stray STX bytes included) sit between frames
// so that `garbage_fraction` of the stream, on average, is noise.
inline MavlinkCapture make_mavlink_capture(std::size_t size, double garbage_fraction) {
  namespace mavlink = protocol::mavlink;
  std::mt19937 rng(42);
  std::normal_distribution<float> jitter(0.0f, 0.05f);
  std::uniform_int_distribution<int> noise(0, 255);
  const double mean_frame_bytes = (3 * 74 + 40) / 4.0;  // HIGHRES_IMU sent truncated (id 0), ATTITUDE
  std::poisson_distribution<int> gap(mean_frame_bytes * garbage_fraction / (1 - garbage_fraction));
  auto n = [&] { return jitter(rng); };
  MavlinkCapture capture;
  std::vector<std::uint8_t>& stream = capture.bytes;
  for (std::uint32_t i = 0; stream.size() < size; ++i, ++capture.frames) {
    const auto seq = static_cast<std::uint8_t>(i);
    if (i % 4 == 3) {
      const mavlink::Attitude attitude{4 * i, n(), n(), 1.5f + n(), n(), n(), n()};
      mavlink::encode(mavlink::make_message(attitude, {.seq = seq}), stream);
    } else {
      const mavlink::HighresImu imu{.time_usec = 4000ull * i,
                                    .xacc = n(),
                                    .yacc = n(),
                                    .zacc = -9.81f + n(),
                                    .xgyro = n(),
                                    .ygyro = n(),
                                    .zgyro = n(),
                                    .xmag = 0.2f + n(),
                                    .ymag = n(),
                                    .zmag = 0.4f + n(),
                                    .abs_pressure = 1013.25f + n(),
                                    .diff_pressure = n(),
                                    .pressure_alt = 100 + n(),
                                    .temperature = 35 + n(),
                                    .fields_updated = 0x1FFF};
      mavlink::encode(mavlink::make_message(imu, {.seq = seq}), stream);
    }
    for (int k = garbage_fraction > 0 ? gap(rng) : 0; k > 0; --k)
      stream.push_back(static_cast<std::uint8_t>(noise(rng)));
  }
  return capture;
}

}  // namespace imubridge::bench
