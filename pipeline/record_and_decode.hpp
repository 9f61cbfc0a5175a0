#pragma once
// A LinkRecorder as the engine's decoding of a link: each chunk, its samples and the decoder's losses are stored
// while the samples go on to the engine. Every writer of recorded sessions decodes through this: the daemon's
// recording links (inside its LinkDecoding, which falls back to decoding alone when the store fails), `sim --db` and
// the imports.
#include <cstdint>
#include <memory>
#include <span>
#include <stdexcept>
#include <utility>
#include <vector>

#include "pipeline/link_decoder.hpp"
#include "pipeline/link_recorder.hpp"
#include "pipeline/session_engine.hpp"
#include "protocol/sample.hpp"

namespace imubridge::pipeline {

class RecordAndDecode final : public ChunkDecoding {
 public:
  // Owns the recorder (begin_recorded_session's). Store failures (store::StoreError) reach the engine's caller.
  explicit RecordAndDecode(std::unique_ptr<LinkRecorder> recorder) : recorder_(std::move(recorder)) {
    if (!recorder_) throw std::invalid_argument("RecordAndDecode: no recorder");
  }
  void decode(std::span<const std::uint8_t> bytes, std::int64_t recv_mono_ns, std::int64_t recv_wall_ns,
              std::vector<protocol::Sample>& out) override {
    recorder_->on_chunk(bytes, recv_mono_ns, recv_wall_ns, out);
  }
  void finish(std::int64_t mono_ns, std::int64_t wall_ns, std::vector<protocol::Sample>& out) override {
    recorder_->finish(mono_ns, wall_ns, out);
  }

  const LinkDecoder& decoder() const { return recorder_->decoder(); }

 private:
  std::unique_ptr<LinkRecorder> recorder_;  // pinned: its decoder points back at it
};

}  // namespace imubridge::pipeline
