#pragma once
// bytes -> samples -> estimates -> sinks: the one path every session takes, live or replayed. A driver (the daemon
// with its serial links, replay with a session's recorded chunks) hands the engine each chunk as it comes; the
// engine decodes it with the link's decoding, estimates every sample (EstimationStage) and gives bytes, samples and
// estimates to each sink in the order the sinks were added. What differs between live and replay is only where
// chunks come from and which sinks listen: the store, the network outputs, the vehicle feedback, the bridge. Writers
// without parameters (`sim --db`, the imports) run it without a stage: decoding (and recording) only.
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

// How a link's chunks become samples: a LinkDecoder (DecodeOnly), or a LinkRecorder that also stores what it
// decodes (RecordAndDecode, pipeline/record_and_decode.hpp).
class ChunkDecoding {
 public:
  virtual ~ChunkDecoding() = default;
  // Appends the samples `bytes` completes.
  virtual void decode(std::span<const std::uint8_t> bytes, std::int64_t recv_mono_ns, std::int64_t recv_wall_ns,
                      std::vector<protocol::Sample>& out) = 0;
  // End of the stream: what the decoder still holds.
  virtual void finish(std::int64_t mono_ns, std::int64_t wall_ns, std::vector<protocol::Sample>& out) = 0;
};

// Decoding alone (replay: the chunks are in the store already; the daemon while it is not recording).
class DecodeOnly final : public ChunkDecoding {
 public:
  explicit DecodeOnly(LinkDecoder& decoder) : decoder_(decoder) {}
  void decode(std::span<const std::uint8_t> bytes, std::int64_t recv_mono_ns, std::int64_t,
              std::vector<protocol::Sample>& out) override {
    decoder_.feed(bytes, recv_mono_ns, out);
  }
  void finish(std::int64_t mono_ns, std::int64_t, std::vector<protocol::Sample>& out) override {
    decoder_.finish(mono_ns, out);
  }

 private:
  LinkDecoder& decoder_;
};

// Something downstream of the engine. Each hook has a default that ignores it, so a sink overrides what it uses.
// An exception from a sink reaches the engine's caller (replay stops on a store error). A live sink catches its own
// failures instead, so that one failing sink never stalls the others or the recording.
class SessionSink {
 public:
  virtual ~SessionSink() = default;
  // A chunk of link `link` as it arrived, before its samples.
  virtual void on_bytes(std::size_t /*link*/, std::span<const std::uint8_t> /*bytes*/, std::int64_t /*recv_mono_ns*/) {}
  // One sample of link `link`, in order, with the estimates it completed: usually none or one, several when a link
  // that waited for its IMU axes releases them. An estimate describes an earlier sample (EstimationStage).
  virtual void on_sample(std::size_t /*link*/, const protocol::Sample& /*sample*/,
                         std::span<const store::Estimate> /*estimates*/, std::int64_t /*recv_mono_ns*/) {}
  // At the end of the data, the estimates of links still waiting for their axes, for no sample of their own.
  virtual void on_final_estimates(std::span<const store::Estimate> /*estimates*/) {}
};

class SessionEngine {
 public:
  // Without a stage (nullptr) the engine decodes only: sinks get every chunk and sample as with one, but no sample
  // carries an estimate and on_final_estimates gets an empty list. For writers that record and keep no estimates.
  explicit SessionEngine(std::unique_ptr<EstimationStage> stage);

  // Sinks are not owned, and are called in the order they were added.
  void add_sink(SessionSink& sink);
  void remove_sink(const SessionSink& sink);
  // A fresh stage, for link ids that changed (a new recording numbers its links anew); nullptr to decode only.
  void replace_stage(std::unique_ptr<EstimationStage> stage);
  // The stage, or nullptr when the engine decodes only.
  EstimationStage* stage() { return stage_.get(); }

  // A chunk of link `link`, decoded by `decoding`: the sinks get its bytes, then each sample with its estimates.
  void on_chunk(std::size_t link, ChunkDecoding& decoding, std::span<const std::uint8_t> bytes,
                std::int64_t recv_mono_ns, std::int64_t recv_wall_ns);
  // The end of link `link`'s stream: its decoder's last samples, estimated and given to the sinks.
  void finish_link(std::size_t link, ChunkDecoding& decoding, std::int64_t mono_ns, std::int64_t wall_ns);
  // The end of the data: links still deciding their IMU axes decide and release their estimates.
  void finish();

 private:
  void estimate(std::size_t link, std::int64_t mono_ns);

  std::unique_ptr<EstimationStage> stage_;  // nullptr: decode only
  std::vector<SessionSink*> sinks_;
  std::vector<protocol::Sample> samples_;   // of the chunk at hand: reused, so a chunk allocates nothing
  std::vector<store::Estimate> estimates_;  // of the sample at hand: reused likewise
};

}  // namespace imubridge::pipeline
