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

LinkRecorder::LinkRecorder(store::Store& store, std::int64_t session, std::int64_t link_id, std::string link_name,
                           protocol::WireFormat format, const protocol::Calibration& calibration,
                           std::optional<protocol::mavlink::ImuSource> mavlink_imu)
    : store_(store),
      session_(session),
      link_id_(link_id),
      link_name_(std::move(link_name)),
      format_name_(protocol::wire_format_name(format)),
      decoder_(
          format, link_id, calibration,
          [this](std::uint64_t source64) {
            auto [it, added] = radio_links_.try_emplace(source64, 0);
            if (added) {
              it->second = store_.add_link(session_, radio_link_name(link_name_, source64), format_name_,
                                           radio_link_description(link_name_, source64));
            }
            return it->second;
          },
          mavlink_imu) {}

void LinkRecorder::lock_mavlink_imu(const MavlinkImuLock& lock) {
  decoder_.lock_mavlink_imu(lock);
  lock_pending_ = !decoder_.mavlink_imu();
}

void LinkRecorder::on_chunk(std::span<const std::uint8_t> bytes, std::int64_t recv_mono_ns, std::int64_t recv_wall_ns,
                            std::vector<protocol::Sample>& samples) {
  store_.append_chunk(session_, link_id_, store::Direction::rx, recv_mono_ns, recv_wall_ns, bytes);
  const std::size_t first = samples.size();
  decoder_.feed(bytes, recv_mono_ns, samples);
  record_lock(recv_mono_ns, recv_wall_ns);
  record_reference(recv_mono_ns, false);
  store_samples(first, samples);
  record_losses(recv_mono_ns, recv_wall_ns);
}

void LinkRecorder::finish(std::int64_t mono_ns, std::int64_t wall_ns, std::vector<protocol::Sample>& samples) {
  const std::size_t first = samples.size();
  decoder_.finish(mono_ns, samples);
  record_lock(mono_ns, wall_ns);
  record_reference(mono_ns, true);
  store_samples(first, samples);
  record_losses(mono_ns, wall_ns);
  nlohmann::json counters;
  for (const auto& [layer, c] : decoder_.counters()) counters[layer] = c;
  counters["frames_without_sample"] = decoder_.frames_without_sample();
  store_.append_event(session_, {.link_id = link_id_,
                                 .mono_ns = mono_ns,
                                 .wall_ns = wall_ns,
                                 .kind = "counters",
                                 .count = 1,
                                 .detail = counters.dump()});
}

void LinkRecorder::record_mavlink_reference(const MavlinkReference::Choice& choice) { reference_.emplace(choice); }

void LinkRecorder::record_reference(std::int64_t mono_ns, bool at_end) {
  if (!reference_) return;
  reference_rows_.clear();
  if (const auto imu = decoder_.mavlink_imu()) reference_->prefer_sender({imu->sysid, imu->compid});
  for (const protocol::mavlink::Message& m : decoder_.mavlink_messages()) {
    reference_->on_message(m, mono_ns, reference_rows_);
  }
  if (at_end) reference_->finish(reference_rows_);
  for (const store::ReferenceRow& row : reference_rows_) store_.append_reference(session_, row);
}

// The IMU a locking link keeps to, once, when it is first heard: for people and tools reading the session (replay
// needs no event: it locks on the same IMU from the same chunks).
void LinkRecorder::record_lock(std::int64_t mono_ns, std::int64_t wall_ns) {
  if (!lock_pending_ || !decoder_.mavlink_imu()) return;
  lock_pending_ = false;
  const protocol::mavlink::ImuSource imu = *decoder_.mavlink_imu();
  store_.append_event(session_,
                      {.link_id = link_id_,
                       .mono_ns = mono_ns,
                       .wall_ns = wall_ns,
                       .kind = "mavlink_imu",
                       .count = 1,
                       .detail = "samples from " + protocol::mavlink::describe(imu) + " only: the first IMU heard"});
}

void LinkRecorder::store_samples(std::size_t first, const std::vector<protocol::Sample>& samples) {
  for (std::size_t i = first; i < samples.size(); ++i) store_.append_sample(session_, samples[i]);
}

// Every loss the decoders counted since the last chunk becomes an event with its count, so a session's losses can
// be read from the store without re-decoding it.
void LinkRecorder::record_losses(std::int64_t mono_ns, std::int64_t wall_ns) {
  const protocol::DecoderCounters now = total(decoder_);
  const auto record = [&](const char* kind, std::uint64_t before, std::uint64_t after, const char* unit) {
    if (after == before) return;
    const auto count = static_cast<std::int64_t>(after - before);
    store_.append_event(session_, {.link_id = link_id_,
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

}  // namespace imubridge::pipeline
