#pragma once
// What the daemon adds downstream of the session engine (pipeline/session_engine.hpp) besides its recording: the
// network outputs, each link's velocity feedback to the vehicle and each link's bridge. Each is a SessionSink of its
// own; make_live_sinks() builds them from the configuration, so a new kind of output is a new sink here and a line
// there, not a change to the daemon.
#include <cstddef>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "daemon/asio.hpp"
#include "daemon/bridge.hpp"
#include "daemon/outputs.hpp"
#include "daemon/vehicle_feedback.hpp"
#include "pipeline/session_engine.hpp"

namespace imubridge::daemon {

// Every sample, with the last estimate it completed, to the outputs (PlotJuggler, line streams), under its link's
// name.
class OutputsSink final : public pipeline::SessionSink {
 public:
  OutputsSink(Outputs& outputs, std::vector<std::string> link_names);
  void on_sample(std::size_t link, const protocol::Sample& sample, std::span<const store::Estimate> estimates,
                 std::int64_t recv_mono_ns) override;

 private:
  Outputs& outputs_;
  std::vector<std::string> link_names_;  // by engine link index
};

// One link's estimates back to its vehicle, as the feedback encodes and paces them.
class FeedbackSink final : public pipeline::SessionSink {
 public:
  using Write = std::function<void(std::span<const std::uint8_t>)>;
  FeedbackSink(std::size_t link, VehicleFeedback& feedback, Write write);
  void on_sample(std::size_t link, const protocol::Sample& sample, std::span<const store::Estimate> estimates,
                 std::int64_t recv_mono_ns) override;

 private:
  std::size_t link_;
  VehicleFeedback& feedback_;
  Write write_;
};

// One link's bytes, as they arrived, to its bridge's endpoints.
class BridgeSink final : public pipeline::SessionSink {
 public:
  BridgeSink(std::size_t link, LinkBridge& bridge);
  void on_chunk(std::size_t link, const pipeline::DecodedChunk& chunk) override;

 private:
  std::size_t link_;
  LinkBridge& bridge_;
};

// What make_live_sinks needs of one configured link; the pointers may be null (no feedback, no bridge).
struct LiveLink {
  std::string name;
  protocol::WireFormat format = protocol::WireFormat::imubridge;
  VehicleFeedback* feedback = nullptr;
  LinkBridge* bridge = nullptr;
  FeedbackSink::Write write;  // bytes to the vehicle on this link
};

// What a live sink may use of the running daemon, besides the engine's calls. Everything here belongs to the
// daemon's thread (the io_context's); a sink with threads of its own posts to `io` to use it.
struct LiveContext {
  boost::asio::io_context& io;
  Outputs& outputs;  // PlotJuggler and line streams; another output's counters join theirs (Outputs::add_counters)
  const OutputsConfig& config;
  // Records an event in the session while recording, nothing otherwise: `link` is the engine's link index, or none
  // for the whole session.
  std::function<void(std::optional<std::size_t> link, std::string kind, std::string detail, std::int64_t count)>
      record_event;
};

// The sinks of a running daemon, in the order the engine calls them: the links' bridges and feedback, then the
// outputs.
std::vector<std::unique_ptr<pipeline::SessionSink>> make_live_sinks(const LiveContext& context,
                                                                    const std::vector<LiveLink>& links);

}  // namespace imubridge::daemon
