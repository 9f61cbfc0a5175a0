// imubridge IMU frame decoding speed, beside the yardstick: one plain byte-at-a-time table CRC pass over the same
// bytes. Target: Decode >= 0.9x CrcBytewise in bytes/s, for the clean and the 5 %-garbage stream alike.
//   scripts/bench imu_decode_bench
#include <benchmark/benchmark.h>

#include <cstdint>
#include <random>
#include <span>
#include <vector>

#include "protocol/crc.hpp"
#include "protocol/imu_frame.hpp"

namespace {

namespace imu = imubridge::protocol::imu;
using Bytes = std::vector<std::uint8_t>;

constexpr std::size_t kStreamBytes = 1 << 20, kChunk = 4096;

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
  const std::span<const std::uint8_t> all(stream);
  std::vector<imu::Frame> frames;
  imubridge::protocol::DecoderCounters counters;
  for (auto _ : state) {
    imu::Decoder decoder;
    for (std::size_t at = 0; at < all.size(); at += kChunk) {
      frames.clear();  // a consumer takes the frames after every chunk
      decoder.feed(all.subspan(at, std::min(kChunk, all.size() - at)), frames);
      benchmark::DoNotOptimize(frames.data());
    }
    decoder.finish();
    counters = decoder.counters();
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * stream.size()));
  state.counters["discarded_pct"] = 100.0 * static_cast<double>(counters.bytes_discarded) / stream.size();
}

void CrcBytewise(benchmark::State& state, double garbage_fraction) {
  const Bytes stream = make_stream(garbage_fraction);
  const std::span<const std::uint8_t> all(stream);
  for (auto _ : state) {
    std::uint16_t crc = imubridge::protocol::kCrc16Init;
    for (std::size_t at = 0; at < all.size(); at += kChunk) {
      crc = imubridge::protocol::crc16_mcrf4xx(all.subspan(at, std::min(kChunk, all.size() - at)), crc);
    }
    benchmark::DoNotOptimize(crc);
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * stream.size()));
}

BENCHMARK_CAPTURE(Decode, clean, 0.0);
BENCHMARK_CAPTURE(CrcBytewise, clean, 0.0);
BENCHMARK_CAPTURE(Decode, garbage_5pct, 0.05);
BENCHMARK_CAPTURE(CrcBytewise, garbage_5pct, 0.05);

}  // namespace
