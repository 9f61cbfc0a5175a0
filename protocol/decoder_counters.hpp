#pragma once
// What every streaming decoder counts (docs/protocol.md, "Counters"). Nothing a decoder drops goes uncounted: every
// byte it was given ends up either inside an emitted frame or in bytes_discarded (or is still buffered, waiting for
// the rest of a frame, until finish()).
#include <concepts>
#include <cstdint>
#include <nlohmann/json_fwd.hpp>

namespace imubridge::protocol {

struct DecoderCounters {
  std::uint64_t bytes_in = 0;         // bytes given to feed()
  std::uint64_t frames_out = 0;       // frames that passed every check and were emitted
  std::uint64_t crc_failures = 0;     // candidates rejected by their CRC / checksum
  std::uint64_t resyncs = 0;          // false starts of any kind (bad CRC, length, escape, version; cut off at the end)
  std::uint64_t bytes_discarded = 0;  // bytes that belong to no emitted frame
  std::uint64_t sequence_gaps = 0;    // times the sequence number jumped (one gap may hide many frames)
  std::uint64_t frames_lost = 0;      // frames missing according to the sequence numbers
  std::uint64_t duplicates = 0;       // valid frames dropped for repeating the sequence number just before them
  std::uint64_t device_restarts = 0;  // the sender restarted: its sequence number and clock both went back
  std::uint64_t unsupported = 0;      // valid frames of a type this decoder does not interpret (counted, not errors)
  std::uint64_t unverified = 0;       // candidates that cannot be checked, so no frames (MAVLink: an unknown id)

  DecoderCounters& operator+=(const DecoderCounters& other);
  // What was counted since `earlier`, the same decoder's counts at an earlier time.
  DecoderCounters& operator-=(const DecoderCounters& earlier);
  friend bool operator==(const DecoderCounters&, const DecoderCounters&) = default;
};

void to_json(nlohmann::json& j, const DecoderCounters& c);

// Counts the step from a sender's previous sequence number to `seq`, both mod 2^bits: 1 is the next frame, k > 1 a
// gap of k - 1 lost frames, and 0 the same number again: a retransmission, which the caller drops. Returns the step.
template <std::unsigned_integral Seq>
Seq count_sequence_step(Seq previous, Seq seq, DecoderCounters& counters) {
  const auto step = static_cast<Seq>(seq - previous);
  if (step == 0) {
    ++counters.duplicates;
  } else if (step > 1) {
    ++counters.sequence_gaps;
    counters.frames_lost += step - 1u;
  }
  return step;
}

// A sender that restarts numbers its frames and counts its clock from zero again, so its next frame is not the next
// number and its time goes back. The next number with its time back is a glitch of the clock, not a restart (the
// estimator drops that sample); a repeat is a retransmission.
template <std::unsigned_integral Seq>
bool is_restart(Seq previous, Seq seq, std::uint64_t previous_time, std::uint64_t time) {
  return time < previous_time && static_cast<Seq>(seq - previous) > 1;
}

}  // namespace imubridge::protocol
