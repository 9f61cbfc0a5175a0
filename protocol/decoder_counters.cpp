#include "protocol/decoder_counters.hpp"

#include <nlohmann/json.hpp>

namespace imubridge::protocol {

DecoderCounters& DecoderCounters::operator+=(const DecoderCounters& other) {
  bytes_in += other.bytes_in;
  frames_out += other.frames_out;
  crc_failures += other.crc_failures;
  resyncs += other.resyncs;
  bytes_discarded += other.bytes_discarded;
  sequence_gaps += other.sequence_gaps;
  frames_lost += other.frames_lost;
  duplicates += other.duplicates;
  device_restarts += other.device_restarts;
  unsupported += other.unsupported;
  unverified += other.unverified;
  return *this;
}

DecoderCounters& DecoderCounters::operator-=(const DecoderCounters& earlier) {
  bytes_in -= earlier.bytes_in;
  frames_out -= earlier.frames_out;
  crc_failures -= earlier.crc_failures;
  resyncs -= earlier.resyncs;
  bytes_discarded -= earlier.bytes_discarded;
  sequence_gaps -= earlier.sequence_gaps;
  frames_lost -= earlier.frames_lost;
  duplicates -= earlier.duplicates;
  device_restarts -= earlier.device_restarts;
  unsupported -= earlier.unsupported;
  unverified -= earlier.unverified;
  return *this;
}

void to_json(nlohmann::json& j, const DecoderCounters& c) {
  j = nlohmann::json{
      {"bytes_in", c.bytes_in},       {"frames_out", c.frames_out},           {"crc_failures", c.crc_failures},
      {"resyncs", c.resyncs},         {"bytes_discarded", c.bytes_discarded}, {"sequence_gaps", c.sequence_gaps},
      {"frames_lost", c.frames_lost}, {"duplicates", c.duplicates},           {"device_restarts", c.device_restarts},           {"unsupported", c.unsupported},
      {"unverified", c.unverified}};
}

}  // namespace imubridge::protocol
