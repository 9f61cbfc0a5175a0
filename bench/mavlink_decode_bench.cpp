// MAVLink decoding speed against a plain byte-at-a-time table CRC pass over the same bytes (bench/decode_bench.hpp).
// Target: x_crc >= 0.9, for the clean and the 5 %-garbage stream alike.
//   scripts/bench mavlink_decode_bench
#include <benchmark/benchmark.h>

#include <cstdint>
#include <random>
#include <span>
#include <vector>

#include "bench/decode_bench.hpp"
#include "protocol/mavlink.hpp"

namespace {

namespace mavlink = imubridge::protocol::mavlink;
using Bytes = std::vector<std::uint8_t>;

constexpr std::size_t kStreamBytes = 1 << 20;

// About 1 MiB of what a PX4 sends when asked for IMU data: MAVLink 2 HIGHRES_IMU frames at the IMU rate with an
// ATTITUDE every fourth, plausible values. With garbage, random bytes (stray STX bytes included) sit between frames
// so that `garbage_fraction` of the stream, on average, is noise.
Bytes make_stream(double garbage_fraction) {
  std::mt19937 rng(42);
  std::normal_distribution<float> jitter(0.0f, 0.05f);
  std::uniform_int_distribution<int> noise(0, 255);
  const double mean_frame_bytes = (3 * 74 + 40) / 4.0;  // HIGHRES_IMU sent truncated (id 0), ATTITUDE
  std::poisson_distribution<int> gap(mean_frame_bytes * garbage_fraction / (1 - garbage_fraction));
  auto n = [&] { return jitter(rng); };
  Bytes stream;
  for (std::uint32_t i = 0; stream.size() < kStreamBytes; ++i) {
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
  return stream;
}

void Decode(benchmark::State& state, double garbage_fraction) {
  const Bytes stream = make_stream(garbage_fraction);
  std::vector<mavlink::Message> messages;
  const auto counters = imubridge::bench::decode_against_crc(
      state, stream, [] { return mavlink::Decoder{}; }, messages);
  state.counters["discarded_pct"] = 100.0 * static_cast<double>(counters.bytes_discarded) / stream.size();
  state.counters["frames"] = static_cast<double>(counters.frames_out);
}

BENCHMARK_CAPTURE(Decode, clean, 0.0)->UseManualTime();
BENCHMARK_CAPTURE(Decode, garbage_5pct, 0.05)->UseManualTime();

}  // namespace
