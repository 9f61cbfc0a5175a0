#pragma once
// Recording, as a sink of the session engine: every chunk exactly as it arrived, the samples decoded from it and
// every loss the decoders counted, as events, and the estimates into the session's run. The engine knows samples by
// their source (a link's index, and an XBee radio's address); the recording maps each source to the store link it is
// stored under, making a store link for each radio as it is first heard (pipeline/radio_link.hpp). The live daemon,
// the simulator and imports record through this, so a session always starts from bytes and replay can reproduce it.
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "pipeline/land_detector.hpp"
#include "pipeline/link_decoder.hpp"
#include "pipeline/mavlink_reference.hpp"
#include "pipeline/recorded_session.hpp"
#include "pipeline/session_engine.hpp"
#include "store/store.hpp"

namespace imubridge::pipeline {

// One link of a recording.
class LinkRecorder {
 public:
  // `row` is the store link of the port, `name` its name. `decoder` is the link's as the recording begins: what it
  // counted before is not this recording's, and a MAVLink lock it still awaits is recorded once it finds its IMU.
  LinkRecorder(store::Store& store, std::int64_t session, std::int64_t row, std::string name,
               const LinkDecoder& decoder);
  LinkRecorder(const LinkRecorder&) = delete;
  LinkRecorder& operator=(const LinkRecorder&) = delete;

  // On a MAVLink link: LOCAL_POSITION_NED and the sender's attitude become the session's reference rows
  // (MavlinkReference), stamped with their chunk's receive time. Without a chosen sender, the IMU's sender is
  // preferred when the link has locked on its IMU by the first position.
  void record_mavlink_reference(const MavlinkReference::Choice& choice = {});
  // The reference being recorded (its rows skipped, its source), or nullptr.
  const MavlinkReference* mavlink_reference() const { return reference_ ? &*reference_ : nullptr; }

  // Stores the chunk, the store links of radios heard for the first time, the IMU a lock found, the reference rows,
  // the land detector's takeoffs and landings, the samples and the losses. At the end of the stream (chunk.end) it ends
  // this link's recording (end()).
  void on_chunk(const DecodedChunk& chunk);
  // The end of this link's recording (the stream's, or the recording's before it: a rotation, a failing store): the
  // reference's last rows, and the decoder's counters since the recording began as an event. Once.
  void end(const LinkDecoder& decoder, std::int64_t mono_ns, std::int64_t wall_ns);
  // The store link of `radio`'s samples (none: the port's own), made when a radio is first stored in this recording.
  std::int64_t row(const std::optional<std::uint64_t>& radio);

 private:
  void add_new_radios(const LinkDecoder& decoder);
  void record_losses(const LinkDecoder& decoder, std::int64_t mono_ns, std::int64_t wall_ns);
  void record_lock(const LinkDecoder& decoder, std::int64_t mono_ns, std::int64_t wall_ns);
  void record_reference(const LinkDecoder& decoder, std::int64_t mono_ns, bool at_end);
  void record_land_detector(const LinkDecoder& decoder, std::int64_t mono_ns, std::int64_t wall_ns);
  void store_samples(std::span<const protocol::Sample> samples);

  store::Store& store_;
  std::int64_t session_;
  std::int64_t row_;
  std::string name_;
  std::string format_name_;
  std::map<std::uint64_t, std::int64_t> radio_rows_;  // XBee source64 -> store link
  std::size_t radios_seen_ = 0;                       // of decoder.radios(): those heard before are stored when heard
  std::optional<MavlinkReference> reference_;
  std::vector<store::ReferenceRow> reference_rows_;  // reused
  bool lock_pending_ = false;                        // a lock whose IMU is not yet recorded
  MavlinkLandDetectorChanges land_detector_;
  // The decoder's counts as the recording began, by framing layer, and its frames without a sample.
  std::vector<std::pair<std::string, protocol::DecoderCounters>> counted_before_;
  std::uint64_t without_sample_before_ = 0;
  protocol::DecoderCounters recorded_;  // losses already written as events (or before), summed over framing layers
  bool ended_ = false;
};

// A recorded session as the engine's sink: its links' recorders, in the engine's order, and its run.
class SessionRecording final : public SessionSink {
 public:
  // Records `session` (begin_recorded_session's, begun with `links`) of the links of `engine`, in the same order.
  SessionRecording(store::Store& store, const RecordedSession& session, const std::vector<SessionLink>& links,
                   const SessionEngine& engine);

  void on_chunk(std::size_t link, const DecodedChunk& chunk) override { recorders_.at(link)->on_chunk(chunk); }
  // The estimates into the run, if there is one (the samples are stored with their chunk).
  void on_sample(std::size_t link, const protocol::Sample& sample, std::span<const store::Estimate> estimates,
                 std::int64_t recv_mono_ns) override;
  void on_final_estimates(const protocol::SourceKey& source, std::span<const store::Estimate> estimates) override;

  // The store link that `source`'s samples, estimates and events are stored under.
  std::int64_t row(const protocol::SourceKey& source) { return recorders_.at(source.link)->row(source.radio); }
  const LinkRecorder& link(std::size_t index) const { return *recorders_.at(index); }
  // Ends the recording of each link whose stream has not ended (LinkRecorder::end). The session is the caller's to
  // end (end_recorded_session).
  void end(const SessionEngine& engine, std::int64_t mono_ns, std::int64_t wall_ns);

 private:
  void append(const protocol::SourceKey& source, std::span<const store::Estimate> estimates);

  store::Store& store_;
  std::optional<std::int64_t> run_;
  std::vector<std::unique_ptr<LinkRecorder>> recorders_;  // LinkRecorder holds a reference: it cannot move
};

}  // namespace imubridge::pipeline
