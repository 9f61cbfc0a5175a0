#include "daemon/live_sinks.hpp"

#include <utility>

#include "daemon/foxglove_output.hpp"
#include "daemon/mqtt_output.hpp"

namespace imubridge::daemon {

OutputsSink::OutputsSink(Outputs& outputs, std::vector<std::string> link_names)
    : outputs_(outputs), link_names_(std::move(link_names)) {}

void OutputsSink::on_sample(std::size_t link, const protocol::Sample& sample,
                            std::span<const store::Estimate> estimates, std::int64_t) {
  outputs_.publish(link_names_.at(link), sample, estimates.empty() ? nullptr : &estimates.back());
}

FeedbackSink::FeedbackSink(std::size_t link, VehicleFeedback& feedback, Write write)
    : link_(link), feedback_(feedback), write_(std::move(write)) {}

void FeedbackSink::on_sample(std::size_t link, const protocol::Sample&, std::span<const store::Estimate> estimates,
                             std::int64_t recv_mono_ns) {
  if (link != link_) return;
  for (const store::Estimate& estimate : estimates) {
    if (auto bytes = feedback_.on_estimate(estimate, recv_mono_ns)) write_(*bytes);
  }
}

BridgeSink::BridgeSink(std::size_t link, LinkBridge& bridge) : link_(link), bridge_(bridge) {}

void BridgeSink::on_chunk(std::size_t link, const pipeline::DecodedChunk& chunk) {
  if (link == link_ && !chunk.bytes.empty()) bridge_.from_link(chunk.bytes);
}

std::vector<std::unique_ptr<pipeline::SessionSink>> make_live_sinks(const LiveContext& context,
                                                                    const std::vector<LiveLink>& links) {
  std::vector<std::unique_ptr<pipeline::SessionSink>> sinks;
  std::vector<std::string> names;
  for (std::size_t i = 0; i < links.size(); ++i) {
    const LiveLink& link = links[i];
    names.push_back(link.name);
    if (link.bridge) sinks.push_back(std::make_unique<BridgeSink>(i, *link.bridge));
    if (link.feedback) sinks.push_back(std::make_unique<FeedbackSink>(i, *link.feedback, link.write));
  }
  if (context.config.mqtt) sinks.push_back(std::make_unique<MqttSink>(*context.config.mqtt, links, context));
  if (context.config.foxglove) {
    sinks.push_back(std::make_unique<FoxgloveSink>(*context.config.foxglove, links, context));
  }
  sinks.push_back(std::make_unique<OutputsSink>(context.outputs, std::move(names)));
  return sinks;
}

}  // namespace imubridge::daemon
