// libFuzzer target for the MAVLink decoder. Input: two bytes that choose a split point, then the byte stream.
// Checks: the stream decoded whole and in two pieces, each through finish(), gives the same messages and counters;
// every byte is in an emitted frame or counted as discarded; no component's message repeats the number of its previous
// one (repeats are dropped as duplicates); the messages, encoded again, decode back to themselves; typed fields
// re-encode to the payload bytes they came from; JSON and sample conversion take anything.
#include <algorithm>
#include <cstdint>
#include <map>
#include <nlohmann/json.hpp>
#include <span>
#include <vector>

#include "fuzz/fuzz_require.hpp"
#include "protocol/mavlink.hpp"
#include "tests/support/decoder_harness.hpp"

namespace mavlink = imubridge::protocol::mavlink;
namespace harness = imubridge::protocol::harness;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 2) return 0;
  const std::span<const std::uint8_t> stream(data + 2, size - 2);
  const std::size_t split = (data[0] | data[1] << 8) % (stream.size() + 1);

  const auto whole = harness::decode_pieces(mavlink::Decoder{}, {stream});
  const auto parts = harness::decode_split(mavlink::Decoder{}, stream, split);
  FUZZ_REQUIRE(parts.frames == whole.frames);
  FUZZ_REQUIRE(parts.counters == whole.counters);

  std::vector<std::uint8_t> again;
  for (const mavlink::Message& m : whole.frames) mavlink::encode(m, again);
  const auto& c = whole.counters;
  FUZZ_REQUIRE(c.bytes_in == stream.size());
  FUZZ_REQUIRE(c.frames_out == whole.frames.size());
  FUZZ_REQUIRE(c.bytes_in == again.size() + c.bytes_discarded);
  FUZZ_REQUIRE(harness::decode_pieces(mavlink::Decoder{}, {again}).frames == whole.frames);

  std::map<int, int> last_seq;  // by sysid << 8 | compid
  for (const mavlink::Message& m : whole.frames) {
    const auto [last, first] = last_seq.try_emplace(m.sysid << 8 | m.compid, m.seq);
    FUZZ_REQUIRE(first || last->second != m.seq);
    last->second = m.seq;
  }

  static const auto calibration = imubridge::protocol::Calibration::reference_board();
  for (const mavlink::Message& m : whole.frames) {
    if (const auto typed = mavlink::decode(m)) {
      const std::vector<std::uint8_t> payload = mavlink::encode_payload(*typed);
      FUZZ_REQUIRE(std::equal(payload.begin(), payload.end(), m.payload.begin()));
    }
    (void)nlohmann::json(m).dump();
    (void)mavlink::to_sample(m, &calibration);
  }
  return 0;
}
