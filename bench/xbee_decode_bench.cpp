// XBee decoder throughput against a plain byte-at-a-time table CRC pass over the same bytes (bench/decode_bench.hpp).
// Target: x_crc >= 0.6 in API mode 2 (escaped), clean and with 5 % garbage; mode 1 is reported beside it.
//   scripts/bench xbee_decode_bench
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <span>
#include <vector>

#include "bench/decode_bench.hpp"
#include "protocol/xbee.hpp"

namespace {

using namespace imubridge::protocol;

constexpr std::size_t kStreamBytes = 256 * 1024;
constexpr std::size_t kPayload = 2 * 37;  // two imubridge IMU-sample frames per RX packet

// RX packets with random payloads (so about 1.6 % of payload bytes need escaping in mode 2), with random garbage
// bytes slipped in between packets until they make up `garbage_fraction` of the stream.
std::vector<std::uint8_t> make_stream(xbee::ApiMode mode, double garbage_fraction) {
  std::mt19937 rng(20240521);
  std::uniform_int_distribution<int> byte(0, 255);
  std::vector<std::uint8_t> stream;
  std::size_t garbage = 0;
  while (stream.size() < kStreamBytes) {
    xbee::RxPacket rx{0x0013A20040A1B2C3, 0xFFFE, 0x01, std::vector<std::uint8_t>(kPayload)};
    for (auto& b : rx.payload) b = static_cast<std::uint8_t>(byte(rng));
    xbee::encode({xbee::kRxPacket, std::move(rx)}, mode, stream);
    for (; garbage < garbage_fraction * static_cast<double>(stream.size()); ++garbage) {
      stream.push_back(static_cast<std::uint8_t>(byte(rng)));
    }
  }
  return stream;
}

void BM_XbeeDecode(benchmark::State& state) {
  const auto mode = static_cast<xbee::ApiMode>(state.range(0));
  const auto stream = make_stream(mode, static_cast<double>(state.range(1)) / 100.0);
  std::vector<xbee::Frame> frames;
  imubridge::bench::decode_against_crc(
      state, stream, [mode] { return xbee::Decoder(mode); }, frames);
}
BENCHMARK(BM_XbeeDecode)
    ->ArgNames({"mode", "garbage_pct"})
    ->Args({1, 0})
    ->Args({2, 0})
    ->Args({1, 5})
    ->Args({2, 5})
    ->UseManualTime();

}  // namespace
