// XBee decoder properties on arbitrary input, in API mode 1 (fuzz/xbee_escaped_fuzz.cpp runs them in mode 2).
// Input: two bytes choosing a split point, then the byte stream.
//  - Decoding the stream whole or in two chunks split at that point, each through finish(), gives the same frames and
//    counters.
//  - Every byte is accounted for: bytes_in == wire bytes of the emitted frames + bytes_discarded.
//  - Each emitted frame re-encodes to the very bytes it came from, and the re-encoded frames decode back to themselves.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <span>
#include <vector>

#include "protocol/xbee.hpp"
#include "tests/support/decoder_harness.hpp"

#ifndef IMUBRIDGE_XBEE_FUZZ_MODE
#define IMUBRIDGE_XBEE_FUZZ_MODE unescaped
#endif

namespace {

using namespace imubridge::protocol;
constexpr xbee::ApiMode kMode = xbee::ApiMode::IMUBRIDGE_XBEE_FUZZ_MODE;

using Decoded = harness::Decoded<xbee::Decoder>;

void require(bool ok, const char* property) {
  if (ok) return;
  std::fprintf(stderr, "xbee fuzz: %s\n", property);
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 2) return 0;
  const std::span<const std::uint8_t> stream(data + 2, size - 2);
  const std::size_t split = (data[0] | std::size_t{data[1]} << 8) % (stream.size() + 1);

  const Decoded whole = harness::decode_pieces(xbee::Decoder(kMode), {stream});
  const Decoded halves = harness::decode_split(xbee::Decoder(kMode), stream, split);
  require(halves.frames == whole.frames, "a split changed the frames");
  require(halves.counters == whole.counters, "a split changed the counters");

  std::vector<std::uint8_t> reencoded;
  auto from = stream.begin();
  for (const xbee::Frame& frame : whole.frames) {
    const std::size_t start = reencoded.size();
    xbee::encode(frame, kMode, reencoded);
    const auto wire = std::span(reencoded).subspan(start);
    from = std::search(from, stream.end(), wire.begin(), wire.end());
    require(from != stream.end(), "a frame's encoding is not the bytes it came from");
    from += static_cast<std::ptrdiff_t>(wire.size());
  }
  require(whole.counters.bytes_in == reencoded.size() + whole.counters.bytes_discarded, "bytes unaccounted for");

  const Decoded again = harness::decode_pieces(xbee::Decoder(kMode), {reencoded});
  require(again.frames == whole.frames, "re-encoded frames decode differently");
  require(again.counters.bytes_discarded == 0 && again.counters.resyncs == 0, "re-encoded frames have false starts");
  return 0;
}
