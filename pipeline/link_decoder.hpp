#pragma once
// Bytes -> samples for one serial link: the protocol's decoder, the calibration, and sequence numbers unwrapped to
// 64 bits. Live runs feed it the chunks read from a port; replay feeds it the same chunks from the store.
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "protocol/calibration.hpp"
#include "protocol/decoder_counters.hpp"
#include "protocol/mavlink.hpp"
#include "protocol/sample.hpp"
#include "protocol/wire_format.hpp"

namespace imubridge::pipeline {

class LinkDecoder {
 public:
  // On an XBee link every radio (64-bit source address) is a sample stream of its own; the resolver gives the link id
  // its samples carry (the recorder makes one store link per radio). Without a resolver they all carry link_id.
  using SourceResolver = std::function<protocol::LinkId(std::uint64_t source64)>;

  // On a MAVLink link every IMU message gives a sample unless `mavlink_imu` names the one IMU to take samples from;
  // the others' messages then count as frames without a sample, like ATTITUDE.
  LinkDecoder(protocol::WireFormat format, protocol::LinkId link_id, const protocol::Calibration& calibration,
              SourceResolver resolve_source = {}, std::optional<protocol::mavlink::ImuSource> mavlink_imu = {});
  ~LinkDecoder();
  LinkDecoder(LinkDecoder&&) noexcept;
  LinkDecoder& operator=(LinkDecoder&&) noexcept;

  // Appends the samples that `chunk` completes, stamped with the chunk's receive time.
  void feed(std::span<const std::uint8_t> chunk, std::int64_t recv_mono_ns, std::vector<protocol::Sample>& out);
  // End of stream: frames recoverable from the buffered tail come out, the rest is counted as discarded.
  void finish(std::int64_t recv_mono_ns, std::vector<protocol::Sample>& out);

  // Each framing layer's counters by name: "imubridge", or "xbee" and the "imubridge" frames inside, or "mavlink".
  std::vector<std::pair<std::string, protocol::DecoderCounters>> counters() const;
  // Frames that were valid but carried no sample (ATTITUDE, HEARTBEAT, velocity echoes, ...).
  std::uint64_t frames_without_sample() const;
  protocol::WireFormat format() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imubridge::pipeline
