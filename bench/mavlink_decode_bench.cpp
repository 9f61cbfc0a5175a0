// MAVLink decoding speed against a plain byte-at-a-time table CRC pass over the same bytes (bench/decode_bench.hpp).
// Target: x_crc >= 0.9, for the clean and the 5 %-garbage stream alike.
//   scripts/bench mavlink_decode_bench
#include <benchmark/benchmark.h>

#include <cstdint>
#include <vector>

#include "bench/decode_bench.hpp"
#include "bench/mavlink_capture.hpp"
#include "protocol/mavlink.hpp"

namespace {

namespace mavlink = imubridge::protocol::mavlink;

constexpr std::size_t kStreamBytes = 1 << 20;

void Decode(benchmark::State& state, double garbage_fraction) {
  const auto stream = imubridge::bench::make_mavlink_capture(kStreamBytes, garbage_fraction).bytes;
  std::vector<mavlink::Message> messages;
  const auto counters = imubridge::bench::decode_against_crc(
      state, stream, [] { return mavlink::Decoder{}; }, messages);
  state.counters["discarded_pct"] = 100.0 * static_cast<double>(counters.bytes_discarded) / stream.size();
  state.counters["frames"] = static_cast<double>(counters.frames_out);
}

BENCHMARK_CAPTURE(Decode, clean, 0.0)->UseManualTime();
BENCHMARK_CAPTURE(Decode, garbage_5pct, 0.05)->UseManualTime();

}  // namespace
