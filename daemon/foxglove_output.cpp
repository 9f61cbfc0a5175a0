#include "daemon/foxglove_output.hpp"

// clang-format off: <utility> first, for Boost 1.74 (daemon/asio.hpp)
#include "daemon/asio.hpp"
// clang-format on
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <chrono>
#include <map>
#include <stdexcept>
#include <utility>

#include "daemon/daemon_internal.hpp"
#include "daemon/live_sinks.hpp"
#include "daemon/outputs.hpp"

namespace imubridge::daemon {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;
using namespace std::chrono_literals;

constexpr const char* kSubprotocol = "foxglove.websocket.v1";
// How often drops are logged, recorded and sent as events while they go on.
constexpr auto kReportInterval = 5s;
// The kernel's share of a client's backlog: small, so that a slow client shows in its own queue (which is counted)
// rather than in socket buffers that autotuning grows to megabytes.
constexpr int kSocketSendBuffer = 256 * 1024;
// A client's requests (subscribe, unsubscribe) are small; nothing bigger is read.
constexpr std::size_t kMaxClientMessage = 64 * 1024;

constexpr std::uint8_t kMessageDataOpcode = 0x01;

std::uint32_t channel_id(std::size_t link, TelemetryFeed::Kind kind) {
  return static_cast<std::uint32_t>(1 + link * TelemetryFeed::kKinds + static_cast<std::size_t>(kind));
}
std::size_t link_of(std::uint32_t channel) { return (channel - 1) / TelemetryFeed::kKinds; }

// The JSON schemas of the three kinds of message: the line streams' members (docs/outputs.md), which Foxglove Studio
// lists as the topics' fields. A number that is not finite is written as null, so each number may be one.
nlohmann::json number(const char* description) {
  return {{"type", nlohmann::json::array({"number", "null"})}, {"description", description}};
}
nlohmann::json xyz_schema(const char* unit) {
  return {{"type", "object"}, {"properties", {{"x", number(unit)}, {"y", number(unit)}, {"z", number(unit)}}}};
}
nlohmann::json sample_schema(bool with_estimate) {
  nlohmann::json properties{
      {"timestamp", {{"type", "number"}, {"description", "device time, s"}}},
      {"link", {{"type", "string"}}},
      {"seq", {{"type", "integer"}, {"description", "the sample's sequence number"}}},
      {"accel", xyz_schema("specific force, m/s^2, IMU axes")},
      {"gyro", xyz_schema("angular rate, rad/s, IMU axes")},
      {"mag", xyz_schema("magnetic field, uT (when the sample has one)")},
      {"temperature", number("degrees Celsius (when the sample has one)")},
      {"recv_wall_ns", {{"type", "integer"}, {"description", "the chunk's arrival, ns since the Unix epoch"}}}};
  if (with_estimate) {
    properties["estimate"] = {{"type", "object"},
                              {"properties",
                               {{"seq", {{"type", "integer"}, {"description", "the sample it describes"}}},
                                {"fx", number("compensated specific force, m/s^2")},
                                {"fy", number("compensated specific force, m/s^2")},
                                {"vx", number("body-frame horizontal velocity, m/s")},
                                {"vy", number("body-frame horizontal velocity, m/s")},
                                {"sx", number("standard deviation of vx, m/s")},
                                {"sy", number("standard deviation of vy, m/s")}}}};
  }
  return {{"type", "object"}, {"properties", properties}};
}
nlohmann::json event_schema() {
  return {{"type", "object"},
          {"properties",
           {{"timestamp", {{"type", "number"}, {"description", "device time, s, when known"}}},
            {"link", {{"type", "string"}}},
            {"kind", {{"type", "string"}}},
            {"count", {{"type", "integer"}}},
            {"detail", {{"type", "string"}}},
            {"wall_ns", {{"type", "integer"}}}}}};
}

std::string advertise_message(const std::vector<std::string>& links) {
  const std::array<std::pair<const char*, nlohmann::json>, TelemetryFeed::kKinds> kinds{
      {{"sample", sample_schema(false)}, {"estimate", sample_schema(true)}, {"event", event_schema()}}};
  const std::array<const char*, TelemetryFeed::kKinds> schema_names{"imubridge.Sample", "imubridge.Estimate",
                                                                    "imubridge.Event"};
  nlohmann::json channels = nlohmann::json::array();
  for (std::size_t link = 0; link < links.size(); ++link) {
    for (std::size_t kind = 0; kind < TelemetryFeed::kKinds; ++kind) {
      channels.push_back({{"id", channel_id(link, static_cast<TelemetryFeed::Kind>(kind))},
                          {"topic", links[link] + "/" + kinds[kind].first},
                          {"encoding", "json"},
                          {"schemaName", schema_names[kind]},
                          {"schema", kinds[kind].second.dump()},
                          {"schemaEncoding", "jsonschema"}});
    }
  }
  return nlohmann::json{{"op", "advertise"}, {"channels", channels}}.dump();
}

std::string status_message(int level, const std::string& text) {
  return nlohmann::json{{"op", "status"}, {"level", level}, {"message", text}}.dump();
}
constexpr int kStatusWarning = 1, kStatusError = 2;

}  // namespace

// One connected client: the WebSocket handshake, its subscriptions, and its queue of frames to write, bounded in
// bytes. Lives on the server's thread; its handlers hold it.
class FoxgloveClient : public std::enable_shared_from_this<FoxgloveClient> {
 public:
  using Totals = FoxgloveSink::ClientTotals;
  FoxgloveClient(tcp::socket socket, std::uint64_t id, std::size_t channels, std::size_t max_queued_bytes,
                 Totals& totals, std::vector<std::shared_ptr<const std::string>> hello)
      : ws_(std::move(socket)),
        id_(id),
        channels_(channels),
        max_queued_bytes_(max_queued_bytes),
        totals_(totals),
        hello_(std::move(hello)) {}

  void start() {
    boost::system::error_code ec;
    ws_.next_layer().set_option(asio::socket_base::send_buffer_size(kSocketSendBuffer), ec);
    ws_.next_layer().set_option(tcp::no_delay(true), ec);
    http::async_read(
        ws_.next_layer(), http_buffer_, request_,
        [self = shared_from_this()](const boost::system::error_code& e, std::size_t) { self->on_request(e); });
  }

  // A message of `channel`, to every subscription of this client to it.
  void send(const FoxgloveSink::Message& message) {
    if (!open_ || !accepted_) return;
    for (const auto& [subscription, channel] : subscriptions_) {
      if (channel != message.channel) continue;
      auto frame = std::make_shared<std::string>();
      frame->reserve(13 + message.payload.size());
      frame->push_back(static_cast<char>(kMessageDataOpcode));
      append_le(*frame, subscription, 4);
      append_le(*frame, static_cast<std::uint64_t>(message.recv_wall_ns), 8);
      *frame += message.payload;
      if (!queue(std::move(frame), /*binary=*/true) && !message.drop_report) {
        ++totals_.dropped_by_link.at(link_of(message.channel));
        ++totals_.dropped;
        // Once per client: which one is slow, for the periodic reports count all clients together.
        if (dropped_++ == 0) {
          spdlog::warn("foxglove: client {} ({}) reads too slowly: messages that do not fit its queue are dropped", id_,
                       remote_);
        }
      }
    }
  }

  // `why`: what ended it, for the log line of a client that was connected.
  void close(std::string_view why = "the server closed") {
    if (!open_) return;
    open_ = false;
    boost::system::error_code ec;
    ws_.next_layer().shutdown(tcp::socket::shutdown_both, ec);
    ws_.next_layer().close(ec);
    if (!accepted_) return;
    --totals_.connected;
    spdlog::info("foxglove: client {} ({}) gone ({}); {} messages dropped for it", id_, remote_, why, dropped_);
  }
  bool is_open() const { return open_; }

 private:
  static void append_le(std::string& out, std::uint64_t value, int bytes) {
    for (int i = 0; i < bytes; ++i) out.push_back(static_cast<char>((value >> (8 * i)) & 0xff));
  }

  void on_request(const boost::system::error_code& ec) {
    if (ec || !open_) return close();
    if (!websocket::is_upgrade(request_)) {
      spdlog::debug("foxglove: client {} sent a request that is not a WebSocket upgrade", id_);
      return close();
    }
    // Foxglove's clients ask for the protocol by name; a browser drops a connection whose answer names another.
    const auto requested = request_[http::field::sec_websocket_protocol];
    const bool speaks_foxglove =
        std::string_view(requested.data(), requested.size()).find(kSubprotocol) != std::string_view::npos;
    ws_.set_option(websocket::stream_base::decorator([speaks_foxglove](websocket::response_type& response) {
      if (speaks_foxglove) response.set(http::field::sec_websocket_protocol, kSubprotocol);
      response.set(http::field::server, "imubridge " IMUBRIDGE_VERSION);
    }));
    ws_.read_message_max(kMaxClientMessage);
    ws_.async_accept(request_, [self = shared_from_this()](const boost::system::error_code& e) {
      if (e || !self->open_) return self->close();
      self->accepted_ = true;
      ++self->totals_.connected;
      self->remote_ = self->remote();
      spdlog::info("foxglove: client {} connected from {}", self->id_, self->remote_);
      for (const auto& text : self->hello_) self->queue(text, /*binary=*/false);
      self->read();
    });
  }

  std::string remote() const {
    boost::system::error_code ec;
    const auto endpoint = ws_.next_layer().remote_endpoint(ec);
    return ec ? std::string("?") : endpoint.address().to_string() + ":" + std::to_string(endpoint.port());
  }

  void read() {
    ws_.async_read(read_buffer_, [self = shared_from_this()](const boost::system::error_code& ec, std::size_t) {
      if (ec || !self->open_) return self->close(ec.message());
      const std::string text = beast::buffers_to_string(self->read_buffer_.data());
      self->read_buffer_.consume(self->read_buffer_.size());
      if (self->ws_.got_text()) {
        self->on_text(text);
      } else {
        self->reply(kStatusWarning, "imubridge publishes only: client messages are not taken");
      }
      self->read();
    });
  }

  void on_text(const std::string& text) {
    nlohmann::json request;
    try {
      request = nlohmann::json::parse(text);
      const std::string op = request.at("op").get<std::string>();
      if (op == "subscribe") {
        for (const auto& subscription : request.at("subscriptions")) {
          const auto id = subscription.at("id").get<std::uint32_t>();
          const auto channel = subscription.at("channelId").get<std::uint32_t>();
          if (channel < 1 || channel > channels_) {
            reply(kStatusError, "subscribe: no channel " + std::to_string(channel));
            continue;
          }
          subscriptions_[id] = channel;
          spdlog::info("foxglove: client {} subscribed to channel {}", id_, channel);
        }
      } else if (op == "unsubscribe") {
        for (const auto& id : request.at("subscriptionIds")) subscriptions_.erase(id.get<std::uint32_t>());
      } else {
        reply(kStatusWarning, "imubridge does not support '" + op + "'");
      }
    } catch (const nlohmann::json::exception& e) {
      reply(kStatusError, std::string("a request imubridge cannot read: ") + e.what());
    }
  }

  void reply(int level, const std::string& text) {
    queue(std::make_shared<const std::string>(status_message(level, text)), /*binary=*/false);
  }

  // Whether the frame was queued: one that would take the queue beyond its bound is not.
  bool queue(std::shared_ptr<const std::string> frame, bool binary) {
    if (!open_) return false;
    if (queued_bytes_ + frame->size() > max_queued_bytes_ && !pending_.empty()) return false;
    queued_bytes_ += frame->size();
    pending_.push_back({std::move(frame), binary});
    write();
    return true;
  }

  void write() {
    if (writing_ || pending_.empty() || !open_) return;
    writing_ = true;
    ws_.binary(pending_.front().binary);
    ws_.async_write(asio::buffer(*pending_.front().frame),
                    [self = shared_from_this()](const boost::system::error_code& ec, std::size_t) {
                      self->writing_ = false;
                      if (ec || !self->open_) return self->close(ec.message());
                      self->queued_bytes_ -= self->pending_.front().frame->size();
                      self->pending_.pop_front();
                      ++self->totals_.sent;
                      self->write();
                    });
  }

  struct Frame {
    std::shared_ptr<const std::string> frame;
    bool binary;
  };
  websocket::stream<tcp::socket> ws_;
  std::uint64_t id_;
  std::size_t channels_;
  std::size_t max_queued_bytes_;
  Totals& totals_;
  std::vector<std::shared_ptr<const std::string>> hello_;  // serverInfo and advertise
  beast::flat_buffer http_buffer_, read_buffer_;
  http::request<http::string_body> request_;
  std::map<std::uint32_t, std::uint32_t> subscriptions_;  // subscription id -> channel id
  std::deque<Frame> pending_;
  std::size_t queued_bytes_ = 0;
  std::uint64_t dropped_ = 0;
  std::string remote_ = "?";  // address:port, once connected
  bool open_ = true, accepted_ = false, writing_ = false;
};

// The listening socket and the clients, on the server's thread.
class FoxgloveSink::Server : public std::enable_shared_from_this<Server> {
 public:
  Server(asio::io_context& io, const Endpoint& listen, std::size_t channels, std::size_t client_queue_bytes,
         ClientTotals& totals, std::vector<std::shared_ptr<const std::string>> hello)
      : acceptor_(io),
        channels_(channels),
        client_queue_bytes_(client_queue_bytes),
        totals_(totals),
        hello_(std::move(hello)) {
    boost::system::error_code ec;
    const tcp::endpoint address(asio::ip::make_address(listen.host, ec), listen.port);
    if (!ec) acceptor_.open(address.protocol(), ec);
    if (!ec) acceptor_.set_option(tcp::acceptor::reuse_address(true), ec);
    if (!ec) acceptor_.bind(address, ec);
    if (!ec) acceptor_.listen(asio::socket_base::max_listen_connections, ec);
    if (ec) throw std::runtime_error("outputs.foxglove: cannot listen on " + listen.text + ": " + ec.message());
    port_ = acceptor_.local_endpoint().port();
  }
  std::uint16_t port() const { return port_; }

  void accept() {
    acceptor_.async_accept([self = shared_from_this()](const boost::system::error_code& ec, tcp::socket socket) {
      if (!self->acceptor_.is_open()) return;
      if (!ec) {
        ++self->totals_.accepted;
        auto client =
            std::make_shared<FoxgloveClient>(std::move(socket), self->totals_.accepted.load(), self->channels_,
                                             self->client_queue_bytes_, self->totals_, self->hello_);
        client->start();
        self->clients_.push_back(std::move(client));
      }
      self->accept();
    });
  }

  void send(const std::deque<Message>& messages) {
    std::erase_if(clients_, [](const auto& client) { return !client->is_open(); });
    for (const Message& message : messages) {
      for (const auto& client : clients_) client->send(message);
    }
  }

  void close() {
    boost::system::error_code ec;
    acceptor_.close(ec);
    for (const auto& client : clients_) client->close();
    clients_.clear();
  }

 private:
  tcp::acceptor acceptor_;
  std::uint16_t port_ = 0;
  std::size_t channels_;
  std::size_t client_queue_bytes_;
  ClientTotals& totals_;
  std::vector<std::shared_ptr<const std::string>> hello_;
  std::vector<std::shared_ptr<FoxgloveClient>> clients_;
};

FoxgloveSink::FoxgloveSink(const FoxgloveConfig& config, const std::vector<LiveLink>& links, const LiveContext& context)
    : config_(config),
      feed_(links, config.sample_hz, config.estimate_hz,
            [this](std::size_t link, TelemetryFeed::Kind kind, std::string payload, std::int64_t recv_wall_ns) {
              enqueue(link, kind, std::move(payload), recv_wall_ns);
            }),
      io_(context.io),
      outputs_(context.outputs),
      record_event_(context.record_event),
      report_timer_(context.io),
      queue_dropped_unreported_(links.size(), 0),
      clients_(links.size()) {
  const std::string server_info =
      nlohmann::json{{"op", "serverInfo"},
                     {"name", "imubridge " IMUBRIDGE_VERSION},
                     {"capabilities", nlohmann::json::array()},
                     {"metadata", {{"links", nlohmann::json(feed_.link_names()).dump()}}},
                     // A client that reconnects can tell a restarted daemon by it.
                     {"sessionId", std::to_string(::getpid()) + "-" + std::to_string(wall_now_ns())}}
          .dump();
  server_ = std::make_shared<Server>(
      server_io_, config_.listen, links.size() * TelemetryFeed::kKinds, config_.client_queue_bytes, clients_,
      std::vector{std::make_shared<const std::string>(server_info),
                  std::make_shared<const std::string>(advertise_message(feed_.link_names()))});
  server_->accept();
  thread_ = std::thread([this] {
    auto work = asio::make_work_guard(server_io_);
    server_io_.run();
  });
  outputs_.add_counters("foxglove", [this] { return counters(); });
  schedule_report();
  spdlog::info(
      "foxglove: serving ws://{}:{} ({} channels; samples {}, estimates {})",
      config_.listen.host.find(':') == std::string::npos ? config_.listen.host : "[" + config_.listen.host + "]",
      server_->port(), links.size() * TelemetryFeed::kKinds,
      !config_.sample_hz        ? std::string("all")
      : *config_.sample_hz <= 0 ? std::string("off")
                                : fmt::format("at most {} Hz per link", *config_.sample_hz),
      !config_.estimate_hz        ? std::string("all")
      : *config_.estimate_hz <= 0 ? std::string("off")
                                  : fmt::format("at most {} Hz per link", *config_.estimate_hz));
}

FoxgloveSink::~FoxgloveSink() {
  outputs_.remove_counters("foxglove");
  report_timer_.cancel();
  asio::post(server_io_, [this] {
    server_->close();
    server_io_.stop();  // what the closed sockets' handlers would do is nothing
  });
  thread_.join();
}

void FoxgloveSink::on_sample(std::size_t link, const protocol::Sample& sample,
                             std::span<const store::Estimate> estimates, std::int64_t recv_mono_ns) {
  try {
    feed_.on_sample(link, sample, estimates, recv_mono_ns);
  } catch (const std::exception& e) {  // out of memory: this output misses a sample, the recording goes on
    spdlog::error("foxglove: {}", e.what());
  }
}

void FoxgloveSink::enqueue(std::size_t link, TelemetryFeed::Kind kind, std::string payload, std::int64_t recv_wall_ns,
                           bool drop_report) {
  bool was_empty = false;
  {
    std::lock_guard lock(mutex_);
    while (!queue_.empty() && queue_.size() >= config_.queue) {
      ++queue_dropped_unreported_[link_of(queue_.front().channel)];
      ++queue_dropped_;
      queue_.pop_front();
    }
    was_empty = queue_.empty();
    queue_.push_back({channel_id(link, kind), recv_wall_ns, std::move(payload), drop_report});
    ++enqueued_;
  }
  // One wake-up per batch: the server's thread takes everything queued by then.
  if (was_empty) {
    asio::post(server_io_, [this] {
      std::deque<Message> batch;
      {
        std::lock_guard lock(mutex_);
        batch.swap(queue_);
      }
      server_->send(batch);
    });
  }
}

void FoxgloveSink::schedule_report() {
  report_timer_.expires_after(kReportInterval);
  report_timer_.async_wait([this](const boost::system::error_code& ec) {
    if (ec) return;
    report();
    schedule_report();
  });
}

// Drops since the last report, by link: logged, recorded as session events, and sent on the link's event channel.
void FoxgloveSink::report() {
  std::vector<std::uint64_t> queue_dropped(queue_dropped_unreported_.size(), 0);
  {
    std::lock_guard lock(mutex_);
    queue_dropped.swap(queue_dropped_unreported_);
  }
  std::uint64_t for_queue = 0, for_clients = 0;
  const std::int64_t wall_ns = wall_now_ns();
  for (std::size_t link = 0; link < queue_dropped.size(); ++link) {
    const std::uint64_t slow = clients_.dropped_by_link[link].exchange(0);
    for_queue += queue_dropped[link];
    for_clients += slow;
    const std::uint64_t dropped = queue_dropped[link] + slow;
    if (dropped == 0) continue;
    const std::string detail = fmt::format(
        "{} messages of this link dropped for clients that read too slowly, {} with the server's queue full", slow,
        queue_dropped[link]);
    record_event_(link, "foxglove_dropped", detail, static_cast<std::int64_t>(dropped));
    enqueue(link, TelemetryFeed::Kind::event,
            feed_.event_payload(link, "foxglove_dropped", static_cast<std::int64_t>(dropped), detail, std::nullopt,
                                wall_ns),
            wall_ns, /*drop_report=*/true);
  }
  if (for_queue + for_clients > 0) {
    spdlog::warn(
        "foxglove: {} messages dropped for clients that read too slowly (each client's queue is {} bytes) and {} with "
        "the server's queue of {} full since the last report",
        for_clients, config_.client_queue_bytes, for_queue, config_.queue);
  }
}

nlohmann::json FoxgloveSink::counters() const {
  std::lock_guard lock(mutex_);
  return {{"port", server_->port()},
          {"clients", clients_.connected.load()},
          {"accepted", clients_.accepted.load()},
          {"enqueued", enqueued_},
          {"queued", queue_.size()},
          {"queue_dropped", queue_dropped_},
          {"sent", clients_.sent.load()},
          {"client_dropped", clients_.dropped.load()}};
}

}  // namespace imubridge::daemon
