// imubridge's MAVLink decoder side by side with the MAVLink C library's parser, the reference every MAVLink receiver
// is measured against, on the same capture in one process. Target (issue 26): x_c_library >= 4, clean and with 5 %
// garbage.
//
// The C library is not part of imubridge: its headers are generated from MAVLink's XML and come from a clone of
// https://github.com/mavlink/c_library_v2, given at configure time; without it this program is not built.
//   git clone https://github.com/mavlink/c_library_v2 DIR
//   IMUBRIDGE_MAVLINK_C_LIBRARY=DIR scripts/bench mavlink_c_library_bench
//
// Each iteration decodes the capture once with each decoder, taking turns at going first, and times each pass on the
// thread's CPU clock, so that a busy machine slows both alike. bytes_per_second is imubridge's; x_c_library is
// imubridge's speed as a multiple of the C library's, the median over the iterations of that ratio for the two passes
// taken together (a pass slowed by another program on the machine moves the median little), and x_c_library_min and
// _max its spread.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <span>
#include <vector>

#include "bench/decode_bench.hpp"
#include "bench/mavlink_capture.hpp"
#include "common/mavlink.h"  // the C library's common dialect: its CRC_EXTRA table and its parser
#include "protocol/mavlink.hpp"

namespace {

namespace mavlink = imubridge::protocol::mavlink;
using imubridge::bench::thread_cpu_seconds;

constexpr std::size_t kCaptureBytes = 7'400'000;  // the size of the capture issue 26 was measured on

// The C library's fastest way through a stream: its byte-at-a-time framing state machine, with no channel table and
// no signing (mavlink_parse_char adds both around it). Returns the frames it passed.
std::size_t c_library_pass(std::span<const std::uint8_t> stream) {
  mavlink_message_t buffer{}, message{};
  mavlink_status_t status{}, message_status{};
  std::size_t frames = 0;
  for (const std::uint8_t byte : stream) {
    if (mavlink_frame_char_buffer(&buffer, &status, byte, &message, &message_status) == MAVLINK_FRAMING_OK) {
      ++frames;
      benchmark::DoNotOptimize(message);
    }
  }
  return frames;
}

// The fairness check: both decoders must have done the whole job. On a clean capture both find every frame written.
// With garbage imubridge still does, and the C library finds fewer: a stray STX makes it take the bytes its length
// byte promises as one candidate and, when the CRC fails, drop all of them, the frames inside included, where
// imubridge resumes at the byte after the STX. So there it may only find fewer.
void check_frames(const imubridge::bench::MavlinkCapture& capture, std::size_t imubridge_frames,
                  std::size_t c_library_frames, bool garbage) {
  if (imubridge_frames == capture.frames &&
      (garbage ? c_library_frames <= capture.frames : c_library_frames == capture.frames))
    return;
  std::fprintf(stderr, "mavlink_c_library_bench: %zu frames written, imubridge found %zu, the C library %zu\n",
               capture.frames, imubridge_frames, c_library_frames);
  std::abort();
}

void Decode(benchmark::State& state, double garbage_fraction) {
  const auto capture = imubridge::bench::make_mavlink_capture(kCaptureBytes, garbage_fraction);
  const std::span<const std::uint8_t> stream = capture.bytes;
  std::vector<mavlink::Message> messages;
  auto make_decoder = [] { return mavlink::Decoder{}; };

  double imubridge_seconds = 0, c_library_seconds = 0;
  std::vector<double> ratios;
  std::size_t imubridge_frames = 0, c_library_frames = 0;
  bool imubridge_first = false;
  for (auto _ : state) {
    double imubridge_pass = 0, c_library_pass_seconds = 0;
    for (int turn = 0; turn < 2; ++turn) {
      const double start = thread_cpu_seconds();
      if ((turn == 0) == imubridge_first) {
        imubridge_frames = imubridge::bench::decode_pass(stream, make_decoder, messages).frames_out;
        imubridge_pass = thread_cpu_seconds() - start;
      } else {
        c_library_frames = c_library_pass(stream);
        c_library_pass_seconds = thread_cpu_seconds() - start;
      }
    }
    imubridge_first = !imubridge_first;
    check_frames(capture, imubridge_frames, c_library_frames, garbage_fraction > 0);
    state.SetIterationTime(imubridge_pass);
    imubridge_seconds += imubridge_pass;
    c_library_seconds += c_library_pass_seconds;
    ratios.push_back(c_library_pass_seconds / imubridge_pass);
  }
  const double bytes = static_cast<double>(state.iterations()) * static_cast<double>(stream.size());
  state.SetBytesProcessed(static_cast<std::int64_t>(bytes));
  state.counters["c_library_bytes_per_second"] =
      benchmark::Counter(bytes / c_library_seconds, benchmark::Counter::kDefaults, benchmark::Counter::kIs1024);
  std::ranges::sort(ratios);
  state.counters["x_c_library"] = ratios[ratios.size() / 2];
  state.counters["x_c_library_min"] = ratios.front();
  state.counters["x_c_library_max"] = ratios.back();
  state.counters["frames"] = static_cast<double>(imubridge_frames);
  state.counters["c_library_frames"] = static_cast<double>(c_library_frames);
}

BENCHMARK_CAPTURE(Decode, clean, 0.0)->UseManualTime();
BENCHMARK_CAPTURE(Decode, garbage_5pct, 0.05)->UseManualTime();

}  // namespace
