// imubridge IMU frame decoding speed against a plain byte-at-a-time table CRC pass over the same bytes
// (bench/decode_bench.hpp). Target: x_crc >= 0.9, for the clean and the 5 %-garbage stream alike.
//   scripts/bench imu_decode_bench
#include <benchmark/benchmark.h>

#include <cstdint>
#include <random>
#include <span>
#include <vector>

#include "bench/decode_bench.hpp"
#include "protocol/imu_frame.hpp"

namespace {

namespace imu = imubridge::protocol::imu;
using Bytes = std::vector<std::uint8_t>;

constexpr std::size_t kStreamBytes = 1 << 20;

// About 1 MiB of IMU sample frames with plausible counts. With garbage, random bytes (stray sync bytes included)
// sit between frames so that `garbage_fraction` of the stream, on average, is noise.
Bytes make_stream(double garbage_fraction) {
  std::mt19937 rng(42);
  std::uniform_int_distribution<int> count(-2000, 2000), noise(0, 255);
  const double frame_bytes = imu::kHeaderSize + imu::kImuSamplePayloadSize + imu::kCrcSize;
  std::poisson_distribution<int> gap(frame_bytes * garbage_fraction / (1 - garbage_fraction));
  auto c = [&] { return static_cast<std::int16_t>(count(rng)); };
  Bytes stream;
  for (std::uint16_t seq = 0; stream.size() < kStreamBytes; ++seq) {
    const imu::Frame frame{seq, seq, 2500ull * seq,
                           imu::ImuRaw{{c(), c(), c()}, {c(), c(), c()}, {c(), c(), c()}, c()}};
    imu::encode(frame, stream);
    for (int n = garbage_fraction > 0 ? gap(rng) : 0; n > 0; --n)
      stream.push_back(static_cast<std::uint8_t>(noise(rng)));
  }
  return stream;
}

void Decode(benchmark::State& state, double garbage_fraction) {
  const Bytes stream = make_stream(garbage_fraction);
  std::vector<imu::Frame> frames;
  const auto counters = imubridge::bench::decode_against_crc(
      state, stream, [] { return imu::Decoder{}; }, frames);
  state.counters["discarded_pct"] = 100.0 * static_cast<double>(counters.bytes_discarded) / stream.size();
}

BENCHMARK_CAPTURE(Decode, clean, 0.0)->UseManualTime();
BENCHMARK_CAPTURE(Decode, garbage_5pct, 0.05)->UseManualTime();

}  // namespace
