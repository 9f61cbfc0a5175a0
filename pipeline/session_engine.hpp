#pragma once
// bytes -> frames -> samples -> estimates -> sinks: the one path every session takes, live or replayed, recorded or
// not. The engine keeps one LinkDecoder per link for the whole session; a driver (the daemon with its serial links,
// replay with a session's recorded chunks, sim and the imports with the bytes they make) hands it each chunk as it
// comes. The engine decodes it, keys its samples by their source (protocol::SourceKey), estimates every sample
// (EstimationStage) and gives the chunk, the samples and the estimates to each sink in the order the sinks were added.
// Recording is one of the sinks (pipeline::SessionRecording, which maps sources to store links), so nothing upstream
// of the sinks knows whether, or where, the session is stored: a recording that begins, rotates or stops leaves the
// decoders and the filters running. What differs between live and replay is only where chunks come from and which
// sinks listen. Writers without parameters (`sim --db`, the imports) run it without a stage: decoding only.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "pipeline/estimation_stage.hpp"
#include "pipeline/link_decoder.hpp"
#include "protocol/sample.hpp"
#include "store/records.hpp"

namespace imubridge::pipeline {

// A chunk of one link as the engine decoded it.
struct DecodedChunk {
  std::span<const std::uint8_t> bytes{};  // as they arrived; empty at the end of the stream
  std::int64_t recv_mono_ns = 0, recv_wall_ns = 0;
  std::span<const protocol::Sample> samples{};  // what it completed, keyed by source
  const LinkDecoder& decoder;  // the link's, just after it: counters, radios, MAVLink messages and lock
  bool end = false;            // the end of the stream (finish_link): what the decoder still held
};

// Something downstream of the engine. Each hook has a default that ignores it, so a sink overrides what it uses.
// An exception from a sink reaches the engine's caller (replay stops on a store error). A live sink catches its own
// failures instead, so that one failing sink never stalls the others or the recording.
class SessionSink {
 public:
  virtual ~SessionSink() = default;
  // A chunk of link `link`, decoded, before its samples' on_sample; and once more at the end of the link's stream.
  virtual void on_chunk(std::size_t /*link*/, const DecodedChunk& /*chunk*/) {}
  // One sample of link `link`, in order, with the estimates it completed: usually none or one, several when a source
  // that waited for its IMU axes releases them. An estimate describes an earlier sample of the same source
  // (EstimationStage).
  virtual void on_sample(std::size_t /*link*/, const protocol::Sample& /*sample*/,
                         std::span<const store::Estimate> /*estimates*/, std::int64_t /*recv_mono_ns*/) {}
  // At the end of the data, the estimates of a source still waiting for its axes, for no sample of their own.
  virtual void on_final_estimates(const protocol::SourceKey& /*source*/,
                                  std::span<const store::Estimate> /*estimates*/) {}
};

class SessionEngine {
 public:
  // Without a stage (nullptr) the engine decodes only: sinks get every chunk and sample as with one, but no sample
  // carries an estimate and there are no final estimates. For writers that record and keep no estimates.
  explicit SessionEngine(std::unique_ptr<EstimationStage> stage);

  // The next link, decoded by `decoder` for the rest of the session; returns its index (SourceKey::link).
  std::size_t add_link(LinkDecoder decoder);
  const LinkDecoder& decoder(std::size_t link) const { return decoders_.at(link); }
  std::size_t links() const { return decoders_.size(); }

  // Sinks are not owned, and are called in the order they were added.
  void add_sink(SessionSink& sink);
  void remove_sink(const SessionSink& sink);
  // The stage, or nullptr when the engine decodes only.
  EstimationStage* stage() { return stage_.get(); }

  // A chunk of link `link`: the sinks get it decoded, then each of its samples with its estimates.
  void on_chunk(std::size_t link, std::span<const std::uint8_t> bytes, std::int64_t recv_mono_ns,
                std::int64_t recv_wall_ns);
  // The end of link `link`'s stream: its decoder's last samples, given and estimated the same way.
  void finish_link(std::size_t link, std::int64_t mono_ns, std::int64_t wall_ns);
  // The end of the data: sources still deciding their IMU axes decide and release their estimates.
  void finish();

 private:
  void deliver(std::size_t link, const DecodedChunk& chunk);

  std::unique_ptr<EstimationStage> stage_;  // nullptr: decode only
  std::vector<LinkDecoder> decoders_;       // by link index
  std::vector<SessionSink*> sinks_;
  std::vector<protocol::Sample> samples_;   // of the chunk at hand: reused, so a chunk allocates nothing
  std::vector<store::Estimate> estimates_;  // of the sample at hand: reused likewise
};

}  // namespace imubridge::pipeline
