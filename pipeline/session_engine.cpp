#include "pipeline/session_engine.hpp"

#include <algorithm>
#include <utility>

#include "pipeline/land_detector.hpp"

namespace imubridge::pipeline {

SessionEngine::SessionEngine(std::unique_ptr<EstimationStage> stage) : stage_(std::move(stage)) {}

std::size_t SessionEngine::add_link(LinkDecoder decoder) {
  decoders_.push_back(std::move(decoder));
  return decoders_.size() - 1;
}

void SessionEngine::add_sink(SessionSink& sink) { sinks_.push_back(&sink); }

void SessionEngine::remove_sink(const SessionSink& sink) { std::erase(sinks_, &sink); }

void SessionEngine::on_chunk(std::size_t link, std::span<const std::uint8_t> bytes, std::int64_t recv_mono_ns,
                             std::int64_t recv_wall_ns) {
  LinkDecoder& decoder = decoders_.at(link);
  samples_.clear();
  decoder.feed(bytes, recv_mono_ns, samples_);
  if (stage_) {
    // The autopilot's land detector, before the chunk's samples: replay, reading the same chunks, applies it at the
    // same sample.
    const auto imu = decoder.mavlink_imu();
    for (const protocol::mavlink::Message& m : decoder.mavlink_messages()) {
      const auto landed = mavlink_landed(m, imu);
      if (landed) stage_->set_landed(static_cast<std::uint32_t>(link), *landed);
    }
  }
  deliver(link, {.bytes = bytes,
                 .recv_mono_ns = recv_mono_ns,
                 .recv_wall_ns = recv_wall_ns,
                 .samples = samples_,
                 .decoder = decoder});
}

void SessionEngine::finish_link(std::size_t link, std::int64_t mono_ns, std::int64_t wall_ns) {
  LinkDecoder& decoder = decoders_.at(link);
  samples_.clear();
  decoder.finish(mono_ns, samples_);
  deliver(link,
          {.recv_mono_ns = mono_ns, .recv_wall_ns = wall_ns, .samples = samples_, .decoder = decoder, .end = true});
}

void SessionEngine::finish() {
  if (!stage_) return;
  stage_->finish([this](const protocol::SourceKey& source, std::span<const store::Estimate> estimates) {
    for (SessionSink* sink : sinks_) sink->on_final_estimates(source, estimates);
  });
}

void SessionEngine::deliver(std::size_t link, const DecodedChunk& chunk) {
  // The decoder knows the radio; which link it decodes is the engine's to say.
  for (protocol::Sample& sample : samples_) sample.source.link = static_cast<std::uint32_t>(link);
  for (SessionSink* sink : sinks_) sink->on_chunk(link, chunk);
  for (const protocol::Sample& sample : samples_) {
    estimates_.clear();
    if (stage_) stage_->update(sample, estimates_);
    for (SessionSink* sink : sinks_) sink->on_sample(link, sample, estimates_, chunk.recv_mono_ns);
  }
}

}  // namespace imubridge::pipeline
