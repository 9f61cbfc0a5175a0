// libFuzzer target for the imubridge IMU frame decoder. The input is a byte stream; it is decoded whole, split in two
// and in small chunks (split point and chunk size taken from the input), each through finish(), and all three must
// agree. Every byte is in an emitted frame or discarded; sequence numbers strictly increase (repeats are dropped as
// duplicates); every frame re-encodes to bytes that occur in the input and decodes back to itself.
#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <vector>

#include "protocol/imu_frame.hpp"
#include "tests/support/decoder_harness.hpp"

namespace {

namespace imu = imubridge::protocol::imu;
namespace harness = imubridge::protocol::harness;
using Bytes = std::vector<std::uint8_t>;
using Decoded = harness::Decoded<imu::Decoder>;

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
  const Decoded whole = harness::decode_pieces(imu::Decoder{}, {input});
  const std::size_t split = size < 2 ? 0 : (data[0] | data[1] << 8) % (size + 1);
  check_same(whole, harness::decode_split(imu::Decoder{}, input, split));
  check_same(whole, harness::decode_chunked(imu::Decoder{}, input, size < 3 ? 1 : data[2] % 32 + 1));

  std::uint64_t in_frames = 0;
  for (const imu::Frame& frame : whole.frames) in_frames += imu::encoded_size(frame);
  check(whole.counters.bytes_in == size);
  check(whole.counters.frames_out == whole.frames.size());
  check(whole.counters.bytes_in == in_frames + whole.counters.bytes_discarded);
  for (std::size_t i = 1; i < whole.frames.size(); ++i) check(whole.frames[i].sequence > whole.frames[i - 1].sequence);

  for (const imu::Frame& frame : whole.frames) {
    const Bytes bytes = bytes_of(frame);
    check(std::search(input.begin(), input.end(), bytes.begin(), bytes.end()) != input.end());
    const Decoded again = harness::decode_pieces(imu::Decoder{}, {bytes});
    check(again.frames.size() == 1 && again.counters.bytes_discarded == 0);
    check(again.frames[0].sequence == frame.seq && bytes_of(again.frames[0]) == bytes);
  }
  return 0;
}
