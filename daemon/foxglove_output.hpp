#pragma once
// A live Foxglove WebSocket server, for Foxglove Studio and any client of Foxglove's published protocol (subprotocol
// foxglove.websocket.v1): per link, one channel of samples, one of estimates and one of events, JSON with a JSON
// schema, the payloads MQTT's (daemon/telemetry_feed.hpp), each message stamped with its chunk's arrival on the wall
// clock. Channels, schemas and limits: docs/outputs.md, "Foxglove".
//
// The recording never waits for a viewer. on_sample, on the daemon's thread, only decimates, writes the JSON and
// appends it to a bounded queue (the oldest message goes when it is full, and is counted); the server's own thread
// (an io_context of its own, Boost.Beast) accepts clients, answers their subscriptions and hands each message to every
// client subscribed to its channel through that client's own queue, bounded in bytes: a client that reads too slowly
// misses messages, counted, and holds up no other. Drops are logged, recorded as session events and sent on the
// links' event channels.
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "daemon/asio.hpp"
#include "daemon/config.hpp"
#include "daemon/telemetry_feed.hpp"
#include "pipeline/session_engine.hpp"

namespace imubridge::daemon {

class Outputs;
struct LiveContext;
struct LiveLink;

class FoxgloveSink final : public pipeline::SessionSink {
 public:
  // Listens before returning: throws std::runtime_error naming the address when it cannot.
  FoxgloveSink(const FoxgloveConfig& config, const std::vector<LiveLink>& links, const LiveContext& context);
  // Closes every client and the listening socket.
  ~FoxgloveSink() override;
  FoxgloveSink(const FoxgloveSink&) = delete;
  FoxgloveSink& operator=(const FoxgloveSink&) = delete;

  void on_sample(std::size_t link, const protocol::Sample& sample, std::span<const store::Estimate> estimates,
                 std::int64_t recv_mono_ns) override;

  // From any thread: what the stats line shows under outputs.foxglove.
  nlohmann::json counters() const;

  // The server's thread's part: the listening socket and the clients (daemon/foxglove_output.cpp).
  class Server;
  // One message for the clients: channel ids are 1 + 3 * link + TelemetryFeed::Kind.
  struct Message {
    std::uint32_t channel;
    std::int64_t recv_wall_ns;
    std::string payload;
    // A report of drops. One a slow client has no room for is not counted as a drop: it would be reported in turn,
    // every kReportInterval for as long as the client stays connected and stuck.
    bool drop_report = false;
  };
  // What the server's thread counts, for the daemon's thread to read.
  struct ClientTotals {
    explicit ClientTotals(std::size_t links) : dropped_by_link(links) {}
    std::atomic<std::uint64_t> accepted{0}, connected{0}, sent{0};  // sent: frames written, to all clients
    std::atomic<std::uint64_t> dropped{0};                          // frames a slow client had no room for
    std::vector<std::atomic<std::uint64_t>> dropped_by_link;        // the same, not yet reported
  };

 private:
  void enqueue(std::size_t link, TelemetryFeed::Kind kind, std::string payload, std::int64_t recv_wall_ns,
               bool drop_report = false);
  void report();
  void schedule_report();

  FoxgloveConfig config_;
  TelemetryFeed feed_;
  boost::asio::io_context& io_;  // the daemon's: logs, events and the report timer happen on its thread
  Outputs& outputs_;
  std::function<void(std::optional<std::size_t>, std::string, std::string, std::int64_t)> record_event_;
  boost::asio::steady_timer report_timer_;

  // Shared by the daemon's thread and the server's: all below, under mutex_.
  mutable std::mutex mutex_;
  std::deque<Message> queue_;
  std::vector<std::uint64_t> queue_dropped_unreported_;  // by link: the queue was full
  std::uint64_t enqueued_ = 0, queue_dropped_ = 0;

  ClientTotals clients_;

  boost::asio::io_context server_io_;
  std::shared_ptr<Server> server_;
  std::thread thread_;
};

}  // namespace imubridge::daemon
