#include "daemon/outputs.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <stdexcept>

namespace imubridge::daemon {
namespace {

// The per-sample messages are written by hand: at 1 kHz, building and dumping a JSON tree per sample cost about a
// tenth of the daemon's CPU (perf, docs/performance.md); the counters below stay nlohmann::json.

// Shortest text that reads back to the same double (std::to_chars); NaN and infinity, which JSON lacks, as null.
// A whole number gets ".0", so that parsers read it as a double: "-0" would come back as the integer 0, losing the
// sign.
void append_number(std::string& out, double value) {
  if (!std::isfinite(value)) {
    out += "null";
    return;
  }
  char text[32];
  char* const end = std::to_chars(text, text + sizeof text, value).ptr;
  out.append(text, end);
  if (std::find_if(text, end, [](char c) { return c == '.' || c == 'e'; }) == end) out += ".0";
}

void append_number(std::string& out, std::uint64_t value) {
  char text[24];
  out.append(text, std::to_chars(text, text + sizeof text, value).ptr);
}

// A JSON string. Link names are plain ASCII (the config checks), but this takes any bytes: quotes, backslashes and
// control characters are escaped, and bytes beyond ASCII become U+FFFD so the message is valid UTF-8 whatever comes.
void append_string(std::string& out, std::string_view text) {
  out += '"';
  for (const char c : text) {
    const auto byte = static_cast<unsigned char>(c);
    if (byte == '"' || byte == '\\') {
      out += '\\';
      out += c;
    } else if (byte < 0x20) {
      constexpr char kHex[] = "0123456789abcdef";
      out += "\\u00";
      out += kHex[byte >> 4];
      out += kHex[byte & 0xf];
    } else if (byte >= 0x80) {
      out += "\\ufffd";
    } else {
      out += c;
    }
  }
  out += '"';
}

// `,"key":` — every key follows another member here, and keys are literals that need no escaping.
void append_key(std::string& out, std::string_view key) {
  out += ",\"";
  out += key;
  out += "\":";
}

void append_xyz(std::string& out, std::string_view key, const std::array<double, 3>& v) {
  append_key(out, key);
  out += "{\"x\":";
  append_number(out, v[0]);
  out += ",\"y\":";
  append_number(out, v[1]);
  out += ",\"z\":";
  append_number(out, v[2]);
  out += '}';
}

// Everything about a sample but its time and link, which the two outputs place differently: the members of one
// object, without its braces.
void append_measurement(std::string& out, const protocol::Sample& s, const store::Estimate* e) {
  out += "\"seq\":";
  append_number(out, s.seq);
  append_xyz(out, "accel", s.accel);
  append_xyz(out, "gyro", s.gyro);
  if (s.has_mag) append_xyz(out, "mag", s.mag);
  if (s.has_temperature) {
    append_key(out, "temperature");
    append_number(out, s.temperature_c);
  }
  if (e == nullptr) return;
  append_key(out, "estimate");
  out += "{\"seq\":";
  append_number(out, e->seq);
  append_key(out, "fx");
  append_number(out, e->fx);
  append_key(out, "fy");
  append_number(out, e->fy);
  append_key(out, "vx");
  append_number(out, e->vx);
  append_key(out, "vy");
  append_number(out, e->vy);
  append_key(out, "sx");
  append_number(out, std::sqrt(e->var_vx));
  append_key(out, "sy");
  append_number(out, std::sqrt(e->var_vy));
  out += '}';
}

}  // namespace

void append_line_members(std::string& out, std::string_view link, const protocol::Sample& sample,
                         const store::Estimate* estimate_or_null) {
  // device_time_us / 1e6 rather than * 1e-6: the quotient is correctly rounded, so 1500000 us is exactly 1.5 s.
  out += "\"timestamp\":";
  append_number(out, static_cast<double>(sample.device_time_us) / 1e6);
  append_key(out, "link");
  append_string(out, link);
  out += ',';
  append_measurement(out, sample, estimate_or_null);
}

Outputs::Outputs(boost::asio::io_context& io, const OutputsConfig& config)
    : io_(io), mqtt_(config.mqtt), foxglove_(config.foxglove) {
  reconfigure(config);
}

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
  if (config.mqtt != mqtt_) {
    spdlog::warn("SIGHUP: [outputs.mqtt] changed; MQTT goes on as started until the daemon is restarted");
  }
  if (config.foxglove != foxglove_) {
    spdlog::warn("SIGHUP: [outputs.foxglove] changed; the server goes on as started until the daemon is restarted");
  }
}

void Outputs::publish(std::string_view link, const protocol::Sample& sample, const store::Estimate* estimate_or_null) {
  auto seen = samples_seen_.find(link);
  if (seen == samples_seen_.end()) seen = samples_seen_.emplace(link, 0).first;
  if (seen->second++ % decimation_ != 0) return;
  ++samples_published_;

  if (!plotjuggler_ && line_streams_.empty()) return;
  if (!line_streams_.empty()) {
    std::string line = "{";
    append_line_members(line, link, sample, estimate_or_null);
    line += "}\n";
    const auto message = std::make_shared<const std::string>(std::move(line));
    for (const auto& stream : line_streams_) stream->send(message);
  }
  if (plotjuggler_) {
    // PlotJuggler names a series by its path and cannot split one by a string field, so the link is a path level.
    std::string& datagram = plotjuggler_->datagram;  // reused: its capacity stays, so no allocation per sample
    datagram = "{\"timestamp\":";
    append_number(datagram, static_cast<double>(sample.device_time_us) / 1e6);  // as append_line_members does
    datagram += ',';
    append_string(datagram, link);
    datagram += ":{";
    append_measurement(datagram, sample, estimate_or_null);
    datagram += "}}";
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
  for (const auto& [name, counters] : other_counters_) j[name] = counters();
  return j;
}

void Outputs::add_counters(std::string name, std::function<nlohmann::json()> counters) {
  other_counters_.insert_or_assign(std::move(name), std::move(counters));
}

void Outputs::remove_counters(std::string_view name) {
  if (const auto it = other_counters_.find(name); it != other_counters_.end()) other_counters_.erase(it);
}

}  // namespace imubridge::daemon
