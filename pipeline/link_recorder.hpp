#pragma once
// Records one link of a session: every received chunk exactly as it arrived, the samples decoded from it, and
// every loss the decoders counted, as events. The live daemon, the simulator and imports record through this, so a
// session always starts from bytes and replay can reproduce it.
#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "pipeline/link_decoder.hpp"
#include "pipeline/mavlink_reference.hpp"
#include "store/store.hpp"

namespace imubridge::pipeline {

class LinkRecorder {
 public:
  // `link_id` is the store link of the port; XBee radios get links of their own (pipeline/radio_link.hpp).
  // `mavlink_imu`: on a MAVLink link, the one IMU whose messages give samples (LinkDecoder).
  LinkRecorder(store::Store& store, std::int64_t session, std::int64_t link_id, std::string link_name,
               protocol::WireFormat format, const protocol::Calibration& calibration,
               std::optional<protocol::mavlink::ImuSource> mavlink_imu = {});
  LinkRecorder(const LinkRecorder&) = delete;  // the decoder's radio resolver points back at this recorder
  LinkRecorder& operator=(const LinkRecorder&) = delete;

  // The decoder's lock (LinkDecoder::lock_mavlink_imu); the IMU it locks on is recorded as a `mavlink_imu` event.
  void lock_mavlink_imu(const MavlinkImuLock& lock);

  // On a MAVLink link: LOCAL_POSITION_NED and the sender's attitude become the session's reference rows
  // (MavlinkReference), stamped with their chunk's receive time. Without a chosen sender, the IMU's sender is
  // preferred when the link has locked on its IMU by the first position.
  void record_mavlink_reference(const MavlinkReference::Choice& choice = {});
  // The reference being recorded (its rows skipped, its source), or nullptr.
  const MavlinkReference* mavlink_reference() const { return reference_ ? &*reference_ : nullptr; }

  // Stores the chunk, decodes it, stores its samples and appends them to `samples`.
  void on_chunk(std::span<const std::uint8_t> bytes, std::int64_t recv_mono_ns, std::int64_t recv_wall_ns,
                std::vector<protocol::Sample>& samples);
  // End of the stream: recovers what the decoders still hold and records the final counters as an event.
  void finish(std::int64_t mono_ns, std::int64_t wall_ns, std::vector<protocol::Sample>& samples);

  const LinkDecoder& decoder() const { return decoder_; }

 private:
  void record_losses(std::int64_t mono_ns, std::int64_t wall_ns);
  void record_lock(std::int64_t mono_ns, std::int64_t wall_ns);
  void record_reference(std::int64_t mono_ns, bool at_end);
  void store_samples(std::size_t first, const std::vector<protocol::Sample>& samples);

  store::Store& store_;
  std::int64_t session_;
  std::int64_t link_id_;
  std::string link_name_;
  std::string format_name_;
  std::map<std::uint64_t, std::int64_t> radio_links_;  // XBee source64 -> store link
  LinkDecoder decoder_;
  std::optional<MavlinkReference> reference_;
  std::vector<store::ReferenceRow> reference_rows_;  // reused
  bool lock_pending_ = false;                        // a lock whose IMU is not yet recorded
  protocol::DecoderCounters recorded_;               // losses already written as events, summed over framing layers
};

}  // namespace imubridge::pipeline
