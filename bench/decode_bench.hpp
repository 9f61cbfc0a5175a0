#pragma once
// What the decode benchmarks share: the yardstick every decoder is held to, a plain byte-at-a-time table CRC-16 pass
// over the same bytes (crc16_mcrf4xx). Each iteration decodes the stream and then runs that pass over it, timing both
// on the thread's CPU clock, so that a busy machine slows both alike. bytes_per_second is the decoder's; x_crc is its
// speed as a multiple of the CRC pass's, the figure the targets are stated in.
#include <benchmark/benchmark.h>
#include <time.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "protocol/crc.hpp"
#include "protocol/decoder_counters.hpp"

namespace imubridge::bench {

inline constexpr std::size_t kChunk = 4096;  // a generous serial read

// The kChunk bytes of `stream` from `at` (fewer at its end): what one serial read delivers.
inline std::span<const std::uint8_t> chunk_at(std::span<const std::uint8_t> stream, std::size_t at) {
  return stream.subspan(at, std::min(kChunk, stream.size() - at));
}

inline double thread_cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

// One decoding pass: a new decoder from make_decoder() over `stream` in kChunk-byte chunks, its frames taken after
// every chunk as a consumer would, then finished. Returns its counters.
template <typename MakeDecoder, typename Frame>
protocol::DecoderCounters decode_pass(std::span<const std::uint8_t> stream, MakeDecoder& make_decoder,
                                      std::vector<Frame>& frames) {
  auto decoder = make_decoder();
  for (std::size_t at = 0; at < stream.size(); at += kChunk) {
    frames.clear();
    decoder.feed(chunk_at(stream, at), frames);
    benchmark::DoNotOptimize(frames.data());
  }
  decoder.finish(frames);
  return decoder.counters();
}

// Each iteration runs decode_pass() and then the CRC pass over the same bytes. Returns the last decoder's counters.
// Register the benchmark with ->UseManualTime().
template <typename MakeDecoder, typename Frame>
protocol::DecoderCounters decode_against_crc(benchmark::State& state, std::span<const std::uint8_t> stream,
                                             MakeDecoder make_decoder, std::vector<Frame>& frames) {
  protocol::DecoderCounters counters;
  double decode_seconds = 0, crc_seconds = 0;
  for (auto _ : state) {
    const double start = thread_cpu_seconds();
    counters = decode_pass(stream, make_decoder, frames);
    const double decoded = thread_cpu_seconds();

    std::uint16_t crc = protocol::kCrc16Init;
    for (std::size_t at = 0; at < stream.size(); at += kChunk) crc = protocol::crc16_mcrf4xx(chunk_at(stream, at), crc);
    benchmark::DoNotOptimize(crc);
    const double crc_done = thread_cpu_seconds();

    state.SetIterationTime(decoded - start);
    decode_seconds += decoded - start;
    crc_seconds += crc_done - decoded;
  }
  const double bytes = static_cast<double>(state.iterations()) * static_cast<double>(stream.size());
  state.SetBytesProcessed(static_cast<std::int64_t>(bytes));
  state.counters["x_crc"] = crc_seconds / decode_seconds;
  state.counters["crc_bytes_per_second"] =
      benchmark::Counter(bytes / crc_seconds, benchmark::Counter::kDefaults, benchmark::Counter::kIs1024);
  return counters;
}

}  // namespace imubridge::bench
