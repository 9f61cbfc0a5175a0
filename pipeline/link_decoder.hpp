#pragma once
// Bytes -> samples for one serial link: the protocol's decoder, the calibration, and sequence numbers unwrapped to
// 64 bits. Live runs feed it the chunks read from a port; replay feeds it the same chunks from the store.
#include <cstdint>
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

// Which IMU a MAVLink link keeps to when it is not named in full: the first IMU heard that this admits (any IMU
// message, or one message, and for HIGHRES_IMU and RAW_IMU one `id`). A live link locks on it (docs/protocol.md,
// "A live MAVLink link"); the lock is a pure function of the bytes, so replay of the same chunks locks on the same IMU.
struct MavlinkImuLock {
  std::optional<std::uint32_t> msgid{};  // none: any IMU message
  std::optional<std::uint8_t> id{};      // none: any id
  bool admits(const protocol::mavlink::ImuSource& source) const {
    return (!msgid || *msgid == source.msgid) && (!id || *id == source.id);
  }
  friend bool operator==(const MavlinkImuLock&, const MavlinkImuLock&) = default;
};

class LinkDecoder {
 public:
  // Samples come out keyed by their XBee radio (SourceKey::radio) on an XBee link, where every radio (64-bit source
  // address) is a stream of its own; SourceKey::link is the engine's to set (SessionEngine keeps one decoder per link).
  // On a MAVLink link every IMU message gives a sample unless `mavlink_imu` names the one IMU to take samples from;
  // the others' messages then count as frames without a sample, like ATTITUDE.
  LinkDecoder(protocol::WireFormat format, const protocol::Calibration& calibration,
              std::optional<protocol::mavlink::ImuSource> mavlink_imu = {});
  ~LinkDecoder();
  LinkDecoder(LinkDecoder&&) noexcept;
  LinkDecoder& operator=(LinkDecoder&&) noexcept;

  // From now on a MAVLink link without a fixed IMU takes samples only from the first IMU `lock` admits; IMU
  // messages before it and from other IMUs count as frames without a sample.
  void lock_mavlink_imu(const MavlinkImuLock& lock);
  // The one IMU a MAVLink link takes samples from: the fixed one, or the one it locked on; none before that.
  std::optional<protocol::mavlink::ImuSource> mavlink_imu() const;
  // A lock is set and has not found its IMU yet.
  bool awaiting_mavlink_imu() const;

  // The XBee radios heard so far (any frame of theirs), in the order each was first heard; empty on other links.
  std::span<const std::uint64_t> radios() const;

  // A MAVLink link's messages of the last feed() or finish(), each whole and checked; empty on other links.
  std::span<const protocol::mavlink::Message> mavlink_messages() const;

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
