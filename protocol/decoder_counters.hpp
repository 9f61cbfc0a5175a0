#pragma once
// What every streaming decoder counts. Nothing a decoder drops goes uncounted: every byte it was given ends up
// either inside a decoded frame or in bytes_discarded (or is still buffered, waiting for the rest of a frame).
#include <cstdint>

#include <nlohmann/json_fwd.hpp>

namespace imubridge::protocol {

struct DecoderCounters {
  std::uint64_t bytes_in = 0;         // bytes given to feed()
  std::uint64_t frames_out = 0;       // frames that passed every check and were emitted
  std::uint64_t crc_failures = 0;     // candidates rejected by their CRC / checksum
  std::uint64_t resyncs = 0;          // false starts of any kind (bad CRC, bad length, bad escape, bad version)
  std::uint64_t bytes_discarded = 0;  // bytes that belong to no emitted frame
  std::uint64_t sequence_gaps = 0;    // times the sequence number jumped (one gap may hide many frames)
  std::uint64_t frames_lost = 0;      // frames missing according to the sequence numbers
  std::uint64_t unsupported = 0;      // valid frames of a type this decoder does not interpret (counted, not errors)

  DecoderCounters& operator+=(const DecoderCounters& other);
  friend bool operator==(const DecoderCounters&, const DecoderCounters&) = default;
};

void to_json(nlohmann::json& j, const DecoderCounters& c);

}  // namespace imubridge::protocol
