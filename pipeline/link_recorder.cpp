#include "pipeline/link_recorder.hpp"

#include <nlohmann/json.hpp>

#include "pipeline/radio_link.hpp"

namespace imubridge::pipeline {
namespace {

protocol::DecoderCounters total(const LinkDecoder& decoder) {
  protocol::DecoderCounters sum;
  for (const auto& [layer, counters] : decoder.counters()) sum += counters;
  return sum;
}

}  // namespace

LinkRecorder::LinkRecorder(store::Store& store, std::int64_t session, std::int64_t row, std::string name,
                           const LinkDecoder& decoder)
    : store_(store),
      session_(session),
      row_(row),
      name_(std::move(name)),
      format_name_(protocol::wire_format_name(decoder.format())),
      radios_seen_(decoder.radios().size()),
      lock_pending_(decoder.awaiting_mavlink_imu()),
      counted_before_(decoder.counters()),
      without_sample_before_(decoder.frames_without_sample()),
      recorded_(total(decoder)) {}

std::int64_t LinkRecorder::row(const std::optional<std::uint64_t>& radio) {
  if (!radio) return row_;
  auto [it, added] = radio_rows_.try_emplace(*radio, 0);
  if (added) {
    it->second =
        store_.add_link(session_, radio_link_name(name_, *radio), format_name_, radio_link_description(name_, *radio));
  }
  return it->second;
}

// A radio gets its store link when first heard, whether or not that frame carried a sample.
void LinkRecorder::add_new_radios(const LinkDecoder& decoder) {
  const auto radios = decoder.radios();
  for (; radios_seen_ < radios.size(); ++radios_seen_) row(radios[radios_seen_]);
}

void LinkRecorder::on_chunk(const DecodedChunk& chunk) {
  if (!chunk.end) {
    store_.append_chunk(session_, row_, store::Direction::rx, chunk.recv_mono_ns, chunk.recv_wall_ns, chunk.bytes);
  }
  add_new_radios(chunk.decoder);
  record_lock(chunk.decoder, chunk.recv_mono_ns, chunk.recv_wall_ns);
  record_reference(chunk.decoder, chunk.recv_mono_ns, false);
  record_land_detector(chunk.decoder, chunk.recv_mono_ns, chunk.recv_wall_ns);
  store_samples(chunk.samples);
  record_losses(chunk.decoder, chunk.recv_mono_ns, chunk.recv_wall_ns);
  if (chunk.end) end(chunk.decoder, chunk.recv_mono_ns, chunk.recv_wall_ns);
}

void LinkRecorder::end(const LinkDecoder& decoder, std::int64_t mono_ns, std::int64_t wall_ns) {
  if (ended_) return;
  ended_ = true;
  record_reference(decoder, mono_ns, true);
  nlohmann::json counters;
  const auto now = decoder.counters();
  // A recording that began after its decoder counts only its own share.
  for (std::size_t i = 0; i < now.size(); ++i) {
    protocol::DecoderCounters own = now[i].second;
    own -= counted_before_[i].second;
    counters[now[i].first] = own;
  }
  counters["frames_without_sample"] = decoder.frames_without_sample() - without_sample_before_;
  store_.append_event(session_, {.link_id = row_,
                                 .mono_ns = mono_ns,
                                 .wall_ns = wall_ns,
                                 .kind = "counters",
                                 .count = 1,
                                 .detail = counters.dump()});
}

void LinkRecorder::record_mavlink_reference(const MavlinkReference::Choice& choice) { reference_.emplace(choice); }

// At the end only the reference's waiting rows: the chunk's messages were taken with it.
void LinkRecorder::record_reference(const LinkDecoder& decoder, std::int64_t mono_ns, bool at_end) {
  if (!reference_) return;
  reference_rows_.clear();
  if (const auto imu = decoder.mavlink_imu()) reference_->prefer_sender({imu->sysid, imu->compid});
  if (!at_end) {
    for (const protocol::mavlink::Message& m : decoder.mavlink_messages()) {
      reference_->on_message(m, mono_ns, reference_rows_);
    }
  } else {
    reference_->finish(reference_rows_);
  }
  for (const store::ReferenceRow& row : reference_rows_) store_.append_reference(session_, row);
}

// The IMU a locking link keeps to, once, when it is first heard: for people and tools reading the session (replay
// needs no event: it locks on the same IMU from the same chunks).
void LinkRecorder::record_lock(const LinkDecoder& decoder, std::int64_t mono_ns, std::int64_t wall_ns) {
  if (!lock_pending_ || !decoder.mavlink_imu()) return;
  lock_pending_ = false;
  const protocol::mavlink::ImuSource imu = *decoder.mavlink_imu();
  store_.append_event(session_,
                      {.link_id = row_,
                       .mono_ns = mono_ns,
                       .wall_ns = wall_ns,
                       .kind = "mavlink_imu",
                       .count = 1,
                       .detail = "samples from " + protocol::mavlink::describe(imu) + " only: the first IMU heard"});
}

// The IMU's autopilot's land detector (EXTENDED_SYS_STATE) changing its mind, as `takeoff` and `landing` events, as
// `import ulog` stores PX4's: what `--in-flight` and `evaluate` read the flight from. Replay needs none: the engine
// reads the same messages from the same chunks.
void LinkRecorder::record_land_detector(const LinkDecoder& decoder, std::int64_t mono_ns, std::int64_t wall_ns) {
  for (const auto& change : land_detector_.after(decoder)) {
    store_.append_event(session_, {.link_id = row_,
                                   .mono_ns = mono_ns,
                                   .wall_ns = wall_ns,
                                   .kind = change.landed ? "landing" : "takeoff",
                                   .count = 1,
                                   .detail = "EXTENDED_SYS_STATE from system " + std::to_string(change.system) +
                                             (change.landed ? ": landed" : ": no longer landed")});
  }
}

void LinkRecorder::store_samples(std::span<const protocol::Sample> samples) {
  for (protocol::Sample sample : samples) {
    sample.link_id = row(sample.source.radio);
    store_.append_sample(session_, sample);
  }
}

// Every loss the decoders counted since the last chunk becomes an event with its count, so a session's losses can
// be read from the store without re-decoding it.
void LinkRecorder::record_losses(const LinkDecoder& decoder, std::int64_t mono_ns, std::int64_t wall_ns) {
  const protocol::DecoderCounters now = total(decoder);
  const auto record = [&](const char* kind, std::uint64_t before, std::uint64_t after, const char* unit) {
    if (after == before) return;
    const auto count = static_cast<std::int64_t>(after - before);
    store_.append_event(session_, {.link_id = row_,
                                   .mono_ns = mono_ns,
                                   .wall_ns = wall_ns,
                                   .kind = kind,
                                   .count = count,
                                   .detail = std::to_string(count) + " " + unit});
  };
  record("sequence_gap", recorded_.frames_lost, now.frames_lost, "frames missing by sequence number");
  record("crc_failure", recorded_.crc_failures, now.crc_failures, "frames failed their CRC/checksum");
  record("bytes_discarded", recorded_.bytes_discarded, now.bytes_discarded, "bytes outside any valid frame");
  record("duplicate", recorded_.duplicates, now.duplicates, "repeated frames dropped");
  record("device_restart", recorded_.device_restarts, now.device_restarts,
         "device restart (its sequence number and clock went back)");
  recorded_ = now;
}

SessionRecording::SessionRecording(store::Store& store, const RecordedSession& session,
                                   const std::vector<SessionLink>& links, const SessionEngine& engine)
    : store_(store), run_(session.run) {
  for (std::size_t i = 0; i < links.size(); ++i) {
    recorders_.push_back(std::make_unique<LinkRecorder>(store, session.id, session.store_links.at(i),
                                                        links[i].recorded.name, engine.decoder(i)));
    if (links[i].mavlink_reference) recorders_.back()->record_mavlink_reference(*links[i].mavlink_reference);
  }
}

void SessionRecording::on_sample(std::size_t, const protocol::Sample& sample,
                                 std::span<const store::Estimate> estimates, std::int64_t) {
  append(sample.source, estimates);
}

void SessionRecording::on_final_estimates(const protocol::SourceKey& source,
                                          std::span<const store::Estimate> estimates) {
  append(source, estimates);
}

void SessionRecording::append(const protocol::SourceKey& source, std::span<const store::Estimate> estimates) {
  if (!run_ || estimates.empty()) return;
  const std::int64_t link = row(source);
  for (store::Estimate estimate : estimates) {
    estimate.link_id = link;
    store_.append_estimate(*run_, estimate);
  }
}

void SessionRecording::end(const SessionEngine& engine, std::int64_t mono_ns, std::int64_t wall_ns) {
  for (std::size_t i = 0; i < recorders_.size(); ++i) recorders_[i]->end(engine.decoder(i), mono_ns, wall_ns);
}

}  // namespace imubridge::pipeline
