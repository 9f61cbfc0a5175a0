// libFuzzer target for the imubridge IMU frame decoder. The input is a byte stream; it is decoded whole, split in two
// and in small chunks (split point and chunk size taken from the input), and all three must agree. Every frame
// must re-encode to bytes that occur in the input and decode back to itself.
#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <vector>

#include "protocol/imu_frame.hpp"

namespace {

namespace imu = imubridge::protocol::imu;
using Bytes = std::vector<std::uint8_t>;

struct Decoded {
  std::vector<imu::Frame> frames;
  imubridge::protocol::DecoderCounters counters;
};

Decoded decode(std::span<const std::uint8_t> stream, std::size_t chunk) {
  imu::Decoder decoder;
  Decoded d;
  for (std::size_t at = 0; at < stream.size(); at += chunk) {
    decoder.feed(stream.subspan(at, std::min(chunk, stream.size() - at)), d.frames);
  }
  decoder.finish();
  d.counters = decoder.counters();
  return d;
}

Decoded decode_split(std::span<const std::uint8_t> stream, std::size_t split) {
  imu::Decoder decoder;
  Decoded d;
  decoder.feed(stream.first(split), d.frames);
  decoder.feed(stream.subspan(split), d.frames);
  decoder.finish();
  d.counters = decoder.counters();
  return d;
}

Bytes bytes_of(const imu::Frame& frame) {
  Bytes out;
  imu::encode(frame, out);
  return out;
}

void check(bool ok) {
  if (!ok) std::abort();
}

// Frames compare by their wire bytes: a velocity estimate may carry NaN, which never equals itself.
void check_same(const Decoded& a, const Decoded& b) {
  check(a.counters == b.counters);
  check(a.frames.size() == b.frames.size());
  for (std::size_t i = 0; i < a.frames.size(); ++i) {
    check(a.frames[i].sequence == b.frames[i].sequence);
    check(bytes_of(a.frames[i]) == bytes_of(b.frames[i]));
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::uint8_t> input(data, size);
  const Decoded whole = decode(input, std::max<std::size_t>(size, 1));
  const std::size_t split = size < 2 ? 0 : (data[0] | data[1] << 8) % (size + 1);
  check_same(whole, decode_split(input, split));
  check_same(whole, decode(input, size < 3 ? 1 : data[2] % 32 + 1));

  std::uint64_t in_frames = 0;
  for (const imu::Frame& frame : whole.frames) in_frames += imu::encoded_size(frame);
  check(whole.counters.bytes_in == size);
  check(whole.counters.frames_out == whole.frames.size());
  check(whole.counters.bytes_in == in_frames + whole.counters.bytes_discarded);

  for (const imu::Frame& frame : whole.frames) {
    const Bytes bytes = bytes_of(frame);
    check(std::search(input.begin(), input.end(), bytes.begin(), bytes.end()) != input.end());
    const Decoded again = decode(bytes, bytes.size());
    check(again.frames.size() == 1 && again.counters.bytes_discarded == 0);
    check(again.frames[0].sequence == frame.seq && bytes_of(again.frames[0]) == bytes);
  }
  return 0;
}
