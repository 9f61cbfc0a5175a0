#include "pipeline/session_engine.hpp"

#include <algorithm>
#include <utility>

namespace imubridge::pipeline {

SessionEngine::SessionEngine(std::unique_ptr<EstimationStage> stage) : stage_(std::move(stage)) {}

void SessionEngine::add_sink(SessionSink& sink) { sinks_.push_back(&sink); }

void SessionEngine::remove_sink(const SessionSink& sink) { std::erase(sinks_, &sink); }

void SessionEngine::replace_stage(std::unique_ptr<EstimationStage> stage) { stage_ = std::move(stage); }

void SessionEngine::on_chunk(std::size_t link, ChunkDecoding& decoding, std::span<const std::uint8_t> bytes,
                             std::int64_t recv_mono_ns, std::int64_t recv_wall_ns) {
  samples_.clear();
  decoding.decode(bytes, recv_mono_ns, recv_wall_ns, samples_);
  for (SessionSink* sink : sinks_) sink->on_bytes(link, bytes, recv_mono_ns);
  estimate(link, recv_mono_ns);
}

void SessionEngine::finish_link(std::size_t link, ChunkDecoding& decoding, std::int64_t mono_ns, std::int64_t wall_ns) {
  samples_.clear();
  decoding.finish(mono_ns, wall_ns, samples_);
  estimate(link, mono_ns);
}

void SessionEngine::finish() {
  estimates_.clear();
  if (stage_) stage_->finish(estimates_);
  for (SessionSink* sink : sinks_) sink->on_final_estimates(estimates_);
}

void SessionEngine::estimate(std::size_t link, std::int64_t mono_ns) {
  for (const protocol::Sample& sample : samples_) {
    estimates_.clear();
    if (stage_) stage_->update(sample, estimates_);
    for (SessionSink* sink : sinks_) sink->on_sample(link, sample, estimates_, mono_ns);
  }
}

}  // namespace imubridge::pipeline
