// libFuzzer target for the MAVLink decoder. Input: two bytes that choose a split point, then the byte stream.
// Checks: the stream decoded whole and in two pieces gives the same messages and counters; every byte is in an
// emitted frame or counted as discarded; the messages, encoded again, decode back to themselves; typed fields
// re-encode to the payload bytes they came from; JSON and sample conversion take anything.
#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <span>
#include <vector>

#include "protocol/mavlink.hpp"

namespace mavlink = imubridge::protocol::mavlink;

namespace {

void require(bool condition) {
  if (!condition) std::abort();
}

struct Decoding {
  std::vector<mavlink::Message> messages;
  imubridge::protocol::DecoderCounters counters;
};

Decoding decode_in_two(std::span<const std::uint8_t> stream, std::size_t split) {
  mavlink::Decoder decoder;
  Decoding d;
  decoder.feed(stream.first(split), d.messages);
  decoder.feed(stream.subspan(split), d.messages);
  decoder.finish(d.messages);
  d.counters = decoder.counters();
  return d;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 2) return 0;
  const std::span<const std::uint8_t> stream(data + 2, size - 2);
  const std::size_t split = (data[0] | data[1] << 8) % (stream.size() + 1);

  const Decoding whole = decode_in_two(stream, stream.size());
  const Decoding parts = decode_in_two(stream, split);
  require(parts.messages == whole.messages);
  require(parts.counters == whole.counters);

  std::vector<std::uint8_t> again;
  for (const mavlink::Message& m : whole.messages) mavlink::encode(m, again);
  const auto& c = whole.counters;
  require(c.bytes_in == stream.size());
  require(c.frames_out == whole.messages.size());
  require(c.bytes_in == again.size() + c.bytes_discarded);
  require(decode_in_two(again, again.size()).messages == whole.messages);

  static const auto calibration = imubridge::protocol::Calibration::reference_board();
  for (const mavlink::Message& m : whole.messages) {
    if (const auto typed = mavlink::decode(m)) {
      const std::vector<std::uint8_t> payload = mavlink::encode_payload(*typed);
      require(std::equal(payload.begin(), payload.end(), m.payload.begin()));
    }
    (void)nlohmann::json(m).dump();
    (void)mavlink::to_sample(m, &calibration);
  }
  return 0;
}
