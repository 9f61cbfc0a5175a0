#include "daemon/outputs.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace imubridge::daemon {
namespace {

using nlohmann::ordered_json;

ordered_json xyz(const std::array<double, 3>& v) { return {{"x", v[0]}, {"y", v[1]}, {"z", v[2]}}; }

// Everything about a sample but its time and link, which the two outputs place differently.
ordered_json measurement(const protocol::Sample& s, const store::Estimate* e) {
  ordered_json j{{"seq", s.seq}, {"accel", xyz(s.accel)}, {"gyro", xyz(s.gyro)}};
  if (s.has_mag) j["mag"] = xyz(s.mag);
  if (s.has_temperature) j["temperature"] = s.temperature_c;
  if (e != nullptr) {
    j["estimate"] = {{"seq", e->seq},
                     {"fx", e->fx},
                     {"fy", e->fy},
                     {"vx", e->vx},
                     {"vy", e->vy},
                     {"sx", std::sqrt(e->var_vx)},
                     {"sy", std::sqrt(e->var_vy)}};
  }
  return j;
}

// NaN and infinity are written as null; bytes that are not UTF-8 (in a link name) as U+FFFD instead of throwing.
std::string dump(const ordered_json& j) { return j.dump(-1, ' ', false, ordered_json::error_handler_t::replace); }

}  // namespace

Outputs::Outputs(boost::asio::io_context& io, const OutputsConfig& config) : io_(io) { reconfigure(config); }

Outputs::~Outputs() {
  for (const auto& stream : line_streams_) stream->close();
}

void Outputs::reconfigure(const OutputsConfig& config) {
  if (config.decimation == 0) throw std::invalid_argument("outputs: decimation must be at least 1");
  if (config.plotjuggler && config.plotjuggler->kind != Endpoint::Kind::udp) {
    throw std::invalid_argument(config.plotjuggler->text + ": PlotJuggler listens on udp:// endpoints only");
  }
  // Open what is new before closing anything, so that a failure leaves the outputs as they were.
  std::unique_ptr<PlotJuggler> plotjuggler;
  const bool keep_plotjuggler =
      config.plotjuggler && plotjuggler_ && same_address(*config.plotjuggler, plotjuggler_->endpoint);
  if (config.plotjuggler && !keep_plotjuggler) {
    plotjuggler = std::make_unique<PlotJuggler>(*config.plotjuggler, open_udp(io_, *config.plotjuggler),
                                                udp_address(*config.plotjuggler));
  }
  std::vector<std::shared_ptr<StreamServer>> streams, opened;
  try {
    for (const Endpoint& endpoint : config.line_streams) {
      const auto old = std::find_if(line_streams_.begin(), line_streams_.end(),
                                    [&](const auto& s) { return same_address(s->endpoint(), endpoint); });
      if (old != line_streams_.end()) {
        streams.push_back(*old);
      } else {
        opened.push_back(StreamServer::start(io_, endpoint, kMaxQueuedBytesPerSubscriber));
        streams.push_back(opened.back());
      }
    }
  } catch (...) {
    for (const auto& stream : opened) stream->close();
    throw;
  }

  for (const auto& stream : line_streams_) {
    if (std::find(streams.begin(), streams.end(), stream) == streams.end()) stream->close();
  }
  line_streams_ = std::move(streams);
  if (!keep_plotjuggler) plotjuggler_ = std::move(plotjuggler);
  decimation_ = config.decimation;
}

void Outputs::publish(std::string_view link, const protocol::Sample& sample, const store::Estimate* estimate_or_null) {
  auto seen = samples_seen_.find(link);
  if (seen == samples_seen_.end()) seen = samples_seen_.emplace(link, 0).first;
  if (seen->second++ % decimation_ != 0) return;
  ++samples_published_;

  if (!plotjuggler_ && line_streams_.empty()) return;
  // device_time_us / 1e6 rather than * 1e-6: the quotient is correctly rounded, so 1500000 us is exactly 1.5 s.
  const double timestamp = static_cast<double>(sample.device_time_us) / 1e6;
  ordered_json body = measurement(sample, estimate_or_null);
  if (!line_streams_.empty()) {
    ordered_json line{{"timestamp", timestamp}, {"link", link}};
    line.update(body);
    const auto message = std::make_shared<const std::string>(dump(line) + '\n');
    for (const auto& stream : line_streams_) stream->send(message);
  }
  if (plotjuggler_) {
    // PlotJuggler names a series by its path and cannot split one by a string field, so the link is a path level.
    const std::string datagram = dump(ordered_json{{"timestamp", timestamp}, {link, std::move(body)}});
    boost::system::error_code ec;
    plotjuggler_->socket.send_to(boost::asio::buffer(datagram), plotjuggler_->target, 0, ec);
    ++(ec ? plotjuggler_->datagrams_dropped : plotjuggler_->datagrams_sent);
  }
}

nlohmann::json Outputs::counters() const {
  nlohmann::json j{
      {"samples_published", samples_published_}, {"plotjuggler", nullptr}, {"line_streams", nlohmann::json::array()}};
  if (plotjuggler_) {
    j["plotjuggler"] = {{"endpoint", plotjuggler_->endpoint.text},
                        {"datagrams_sent", plotjuggler_->datagrams_sent},
                        {"datagrams_dropped", plotjuggler_->datagrams_dropped}};
  }
  for (const auto& stream : line_streams_) {
    const auto totals = stream->totals();
    nlohmann::json subscribers = nlohmann::json::array();
    for (const auto& [id, c] : stream->clients()) {
      subscribers.push_back({{"id", id},
                             {"lines_sent", c.messages_sent},
                             {"lines_dropped", c.messages_dropped},
                             {"lines_queued", c.messages_queued}});
    }
    nlohmann::json s{{"endpoint", stream->endpoint().text},
                     {"accepted", stream->accepted()},
                     {"lines_sent", totals.messages_sent},
                     {"lines_dropped", totals.messages_dropped},
                     {"subscribers", std::move(subscribers)}};
    if (stream->endpoint().kind == Endpoint::Kind::tcp_listen) s["port"] = stream->port();
    j["line_streams"].push_back(std::move(s));
  }
  return j;
}

}  // namespace imubridge::daemon
