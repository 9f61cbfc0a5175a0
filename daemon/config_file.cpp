#include "daemon/config_file.hpp"

#include <toml++/toml.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <stdexcept>

#include "archive/pg_connection.hpp"
#include "daemon/endpoint.hpp"
#include "daemon/toml_table.hpp"
#include "daemon/vehicle_feedback.hpp"
#include "estimator/imu_axes.hpp"
#include "pipeline/session_config.hpp"
#include "protocol/hex.hpp"
#include "protocol/mavlink_messages.hpp"

namespace imubridge::daemon {
namespace {

using nlohmann::json;
constexpr double kMiB = 1024.0 * 1024.0;

toml::array to_toml_array(const json& j);
toml::table to_toml_table(const json& j) {
  toml::table t;
  for (const auto& [k, v] : j.items()) {
    if (v.is_object())
      t.insert_or_assign(k, to_toml_table(v));
    else if (v.is_array())
      t.insert_or_assign(k, to_toml_array(v));
    else if (v.is_number_float())
      t.insert_or_assign(k, v.get<double>());
    else if (v.is_number())
      t.insert_or_assign(k, v.get<std::int64_t>());
    else if (v.is_boolean())
      t.insert_or_assign(k, v.get<bool>());
    else if (v.is_string())
      t.insert_or_assign(k, v.get<std::string>());
  }
  return t;
}
toml::array to_toml_array(const json& j) {
  toml::array a;
  for (const auto& v : j) {
    if (v.is_number_float())
      a.push_back(v.get<double>());
    else if (v.is_number())
      a.push_back(v.get<std::int64_t>());
    else if (v.is_object())
      a.push_back(to_toml_table(v));
  }
  return a;
}

void read_ms(TomlTable& t, std::string_view key, std::chrono::milliseconds& out, std::int64_t min, std::int64_t max) {
  if (auto ms = t.integer(key, min, max)) out = std::chrono::milliseconds(*ms);
}

Endpoint parse_endpoint_at(const TomlTable& t, std::string_view key, const std::string& text) {
  try {
    return parse_endpoint(text);
  } catch (const std::invalid_argument& e) {
    t.fail(key, e.what());
  }
}
std::optional<Endpoint> read_endpoint(TomlTable& t, std::string_view key) {
  const auto text = t.string(key);
  if (!text) return std::nullopt;
  return parse_endpoint_at(t, key, *text);
}
std::vector<Endpoint> read_endpoints(TomlTable& t, std::string_view key) {
  std::vector<Endpoint> out;
  for (const auto& text : t.strings(key)) out.push_back(parse_endpoint_at(t, key, text));
  return out;
}

// Unknown keys of a calibration table are reported like any other: its layout is the reference board's JSON.
protocol::Calibration read_calibration(TomlTable& link) {
  auto table = link.table("calibration");
  if (!table) return protocol::Calibration::reference_board();
  json calibration = pipeline::calibration_to_json(protocol::Calibration::reference_board());
  check_keys(*table, calibration);
  calibration.merge_patch(toml_to_json(table->raw()));  // keys left out keep the reference board's values
  try {
    return pipeline::calibration_from_json(calibration);
  } catch (const std::exception& e) {  // a wrongly typed value, or not a valid calibration
    link.fail("calibration", std::string("is not usable: ") + e.what());
  }
}

DeviceSelector read_device(TomlTable& link) {
  DeviceSelector device;
  const auto path = link.string("device");
  auto usb = link.table("usb");
  if (path.has_value() == usb.has_value()) link.fail("", "needs exactly one of 'device' (a path) and 'usb'");
  if (path) {
    if (path->empty()) link.fail("device", "must not be empty");
    device.path = *path;
    return device;
  }
  const auto vid = usb->integer("vid", 0, 0xFFFF);
  const auto pid = usb->integer("pid", 0, 0xFFFF);
  if (!vid || !pid) usb->fail("", "needs 'vid' and 'pid' (e.g. vid = 0x0403, pid = 0x6001)");
  device.usb_vid = static_cast<std::uint16_t>(*vid);
  device.usb_pid = static_cast<std::uint16_t>(*pid);
  device.usb_serial = usb->string("serial");
  usb->finish();
  return device;
}

LinkConfig read_link(TomlTable& t) {
  LinkConfig link;
  link.name = t.string("name").value_or("");
  if (link.name.empty()) t.fail("", "needs a 'name'");
  link.device = read_device(t);
  if (auto format = t.string("protocol")) {
    try {
      link.format = protocol::parse_wire_format(*format);
    } catch (const std::invalid_argument& e) {
      t.fail("protocol", e.what());
    }
  }
  if (const toml::node* baud = t.find("baud")) {
    const auto* rate = baud->as_integer();
    if (!rate) t.fail("baud", "must be a whole number of bits per second, e.g. 115200");
    try {
      check_baud(rate->get());
    } catch (const std::invalid_argument& e) {
      t.fail("baud", e.what());
    }
    link.baud = static_cast<std::uint32_t>(rate->get());
  }
  link.calibration = read_calibration(t);
  if (auto axes = t.string("axes")) {
    try {
      estimator::parse_imu_axes(*axes);
      link.axes = *axes;
    } catch (const std::invalid_argument& e) {
      t.fail("axes", e.what());
    }
  }
  if (auto imu = t.string("imu")) {
    if (!mavlink_imu_msgid(*imu)) {
      t.fail("imu", "must be one of 'HIGHRES_IMU', 'SCALED_IMU', 'SCALED_IMU2', 'SCALED_IMU3', 'RAW_IMU'");
    }
    link.imu = *imu;
  }
  if (auto id = t.integer("imu_id", 0, 255)) link.imu_id = static_cast<std::uint8_t>(*id);
  if (auto rates = t.table("request_rates")) {
    for (const auto& [key, value] : rates->raw()) {
      const std::string name(key.str());
      if (!mavlink_message_id(name)) rates->fail(name, "is not a MAVLink message name (e.g. HIGHRES_IMU, ATTITUDE)");
      link.request_rates[name] = *rates->number(name, 0.1, 2000);
    }
    rates->finish();
  }
  if (auto id = t.integer("gcs_sysid", 1, 255)) link.gcs_sysid = static_cast<std::uint8_t>(*id);
  if (auto id = t.integer("gcs_compid", 0, 255)) link.gcs_compid = static_cast<std::uint8_t>(*id);
  link.bridge = read_endpoints(t, "bridge");
  if (auto feedback = t.table("feedback")) {
    link.feedback.enabled = feedback->boolean("enabled").value_or(true);
    link.feedback.rate_hz = feedback->number("rate_hz", 0.01, 1000).value_or(link.feedback.rate_hz);
    if (auto destination = feedback->string("xbee_destination64")) {
      try {
        link.feedback.xbee_destination64 = protocol::parse_hex(*destination, 16);
      } catch (const std::invalid_argument& e) {
        feedback->fail("xbee_destination64", e.what());
      }
    }
    feedback->finish();
  }
  read_ms(t, "reconnect_min_ms", link.reconnect_min, 1, 3'600'000);
  read_ms(t, "reconnect_max_ms", link.reconnect_max, 1, 3'600'000);
  t.finish();
  return link;
}

StoreConfig read_store(TomlTable& t) {
  StoreConfig store;
  if (auto path = t.string("path")) store.path = *path;
  read_ms(t, "commit_interval_ms", store.commit_interval, 1, 60'000);
  if (auto mib = t.number("max_size_mib", 0, 1e9)) {
    // Below a fresh database's size every check would rotate again.
    if (*mib > 0 && *mib < 1) t.fail("max_size_mib", "must be 0 (no cap) or at least 1");
    store.max_size_bytes = std::llround(*mib * kMiB);
  }
  if (auto mib = t.number("min_free_mib", 0, 1e9)) store.min_free_bytes = std::llround(*mib * kMiB);
  if (auto on_full = t.choice<StoreConfig::OnFull>(
          "on_full", {{"rotate", StoreConfig::OnFull::rotate}, {"stop", StoreConfig::OnFull::stop}})) {
    store.on_full = *on_full;
  }
  t.finish();
  return store;
}

// mqtt://HOST[:PORT] or mqtts://HOST[:PORT]. Unlike an endpoint's, the host may be a name: libmosquitto resolves it
// on its own thread, so a slow DNS never holds up recording.
void parse_mqtt_url(TomlTable& t, const std::string& text, MqttConfig& mqtt) {
  const auto bad = [&](const std::string& why) {
    t.fail("url", "'" + text + "': " + why + " (expected mqtt://HOST[:PORT] or mqtts://HOST[:PORT])");
  };
  std::string_view rest = text;
  if (rest.starts_with("mqtt://")) {
    rest.remove_prefix(7);
  } else if (rest.starts_with("mqtts://")) {
    rest.remove_prefix(8);
    mqtt.tls = true;
  } else {
    bad("unknown scheme");
  }
  mqtt.port = mqtt.tls ? 8883 : 1883;
  std::string_view host = rest;
  std::optional<std::string_view> port;
  if (rest.starts_with('[')) {  // [IPv6]
    const auto close = rest.find(']');
    if (close == std::string_view::npos) bad("no ']' after the IPv6 address");
    host = rest.substr(1, close - 1);
    const std::string_view after = rest.substr(close + 1);
    if (!after.empty() && !after.starts_with(':')) bad("junk after the IPv6 address");
    if (!after.empty()) port = after.substr(1);
  } else if (const auto colon = rest.find(':'); colon != std::string_view::npos) {
    host = rest.substr(0, colon);
    port = rest.substr(colon + 1);
    if (port->find(':') != std::string_view::npos) bad("an IPv6 address goes in brackets, as in mqtt://[::1]:1883");
  }
  if (host.empty()) bad("no host");
  if (host.find_first_of("/?#@ ") != std::string_view::npos) bad("a host is a name or an address, nothing more");
  if (port) {
    unsigned value = 0;
    const auto [end, ec] = std::from_chars(port->data(), port->data() + port->size(), value);
    if (ec != std::errc() || end != port->data() + port->size() || value < 1 || value > 65535) {
      bad("the port must be a number from 1 to 65535");
    }
    mqtt.port = static_cast<std::uint16_t>(value);
  }
  mqtt.url = text;
  mqtt.host = host;
}

// MQTT topic levels: '/' would add a level and '+', '#' are wildcards, so stations keep to link names' characters.
bool is_plain_name(std::string_view name) {
  return !name.empty() && std::all_of(name.begin(), name.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
  });
}

MqttConfig read_mqtt(TomlTable& t) {
  MqttConfig mqtt;
  const auto url = t.string("url");
  if (!url) t.fail("", "needs a 'url' (mqtt://HOST[:PORT] or mqtts://HOST[:PORT])");
  parse_mqtt_url(t, *url, mqtt);
  const auto station = t.string("station");
  if (!station) t.fail("", "needs a 'station': this ground station's name in the topics, e.g. \"field-1\"");
  if (!is_plain_name(*station)) t.fail("station", "must be letters, digits, '_', '-' or '.' (it is a topic level)");
  mqtt.station = *station;
  if (auto qos = t.integer("qos", 0, 1)) mqtt.qos = static_cast<int>(*qos);
  if (auto hz = t.number("sample_hz", 0, 100'000)) mqtt.sample_hz = *hz;
  mqtt.estimate_hz = t.number("estimate_hz", 0, 100'000);
  if (auto s = t.integer("keepalive_s", 5, 65'535)) mqtt.keepalive = std::chrono::seconds(*s);  // libmosquitto's range
  if (auto s = t.integer("reconnect_min_s", 1, 3600)) mqtt.reconnect_min = std::chrono::seconds(*s);
  if (auto s = t.integer("reconnect_max_s", 1, 3600)) mqtt.reconnect_max = std::chrono::seconds(*s);
  if (mqtt.reconnect_min > mqtt.reconnect_max) t.fail("reconnect_min_s", "is above reconnect_max_s");
  if (auto n = t.integer("outbox", 16, 10'000'000)) mqtt.outbox = static_cast<std::size_t>(*n);
  mqtt.username = t.string("username");
  if (t.find("password")) {
    t.fail("password", "is never written in the configuration: use password_file or password_env");
  }
  if (auto file = t.string("password_file")) mqtt.password_file = *file;
  mqtt.password_env = t.string("password_env");
  if (mqtt.password_file && mqtt.password_env) t.fail("password_env", "and password_file: give one of them");
  if ((mqtt.password_file || mqtt.password_env) && !mqtt.username) {
    t.fail(mqtt.password_file ? "password_file" : "password_env", "needs a 'username'");
  }
  if (auto ca = t.string("ca_file")) {
    if (!mqtt.tls) t.fail("ca_file", "is for mqtts:// URLs");
    mqtt.ca_file = *ca;
  }
  mqtt.client_id = t.string("client_id").value_or("imubridge-" + mqtt.station);
  if (mqtt.client_id.empty()) t.fail("client_id", "must not be empty");
  if (auto version = t.choice<int>("protocol_version", {{"3.1.1", 4}, {"5", 5}})) mqtt.protocol_version = *version;
  t.finish();
  return mqtt;
}

FoxgloveConfig read_foxglove(TomlTable& t) {
  FoxgloveConfig foxglove;
  if (auto listen = t.string("listen")) {
    foxglove.listen = parse_endpoint_at(t, "listen", "tcp-listen://" + *listen);
    foxglove.listen.text = *listen;
  }
  foxglove.sample_hz = t.number("sample_hz", 0, 100'000);
  foxglove.estimate_hz = t.number("estimate_hz", 0, 100'000);
  if (auto n = t.integer("queue", 16, 10'000'000)) foxglove.queue = static_cast<std::size_t>(*n);
  if (auto kib = t.integer("client_queue_kib", 16, 1'048'576)) {
    foxglove.client_queue_bytes = static_cast<std::size_t>(*kib) * 1024;
  }
  t.finish();
  return foxglove;
}

OutputsConfig read_outputs(TomlTable& t) {
  OutputsConfig outputs;
  outputs.plotjuggler = read_endpoint(t, "plotjuggler");
  outputs.line_streams = read_endpoints(t, "line_streams");
  if (auto n = t.integer("decimation", 1, 1'000'000)) outputs.decimation = static_cast<std::uint32_t>(*n);
  if (auto mqtt = t.table("mqtt")) outputs.mqtt = read_mqtt(*mqtt);
  if (auto foxglove = t.table("foxglove")) outputs.foxglove = read_foxglove(*foxglove);
  t.finish();
  return outputs;
}

SyncConfig read_sync(TomlTable& t) {
  SyncConfig sync;
  const auto to = t.string("to");
  if (!to) t.fail("", "needs 'to', the archive's URL: postgresql://USER@HOST[:PORT]/DATABASE");
  if (!to->starts_with("postgresql://") && !to->starts_with("postgres://")) {
    t.fail("to", "must be a postgresql:// URL");
  }
  if (archive::redact_url(*to) != *to || t.find("password")) {
    t.fail(t.find("password") ? "password" : "to",
           "holds a password, which is never written in the configuration: use password_file or password_env");
  }
  sync.to = *to;
  sync.station = t.string("station").value_or("");
  if (auto s = t.integer("interval_s", 1, 86'400)) sync.interval = std::chrono::seconds(*s);
  if (auto chunks = t.boolean("chunks")) sync.chunks = *chunks;
  if (auto file = t.string("password_file")) sync.password_file = *file;
  sync.password_env = t.string("password_env");
  if (sync.password_file && sync.password_env) t.fail("password_env", "and password_file: give one of them");
  t.finish();
  return sync;
}

std::string source_prefix(std::string_view source) {
  return source.empty() ? std::string() : std::string(source) + ": ";
}

}  // namespace

Config parse_config(std::string_view toml_text, std::string_view source) {
  toml::table root;
  try {
    root = toml::parse(toml_text, source);
  } catch (const toml::parse_error& e) {
    std::string what(e.description());
    std::replace(what.begin(), what.end(), '\n', ' ');
    throw std::invalid_argument(std::string(source) + ":" + std::to_string(e.source().begin.line) + ": " + what);
  }
  TomlTable t(root, "", source);
  Config config;
  if (auto level = t.choice<std::string>(
          "log_level",
          {{"trace", "trace"}, {"debug", "debug"}, {"info", "info"}, {"warn", "warn"}, {"error", "error"}})) {
    config.log_level = *level;
  }
  if (auto file = t.string("log_file")) config.log_file = *file;
  if (auto s = t.integer("stats_interval_s", 1, 86'400)) config.stats_interval = std::chrono::seconds(*s);
  if (auto params = t.string("params")) config.params = *params;
  if (auto store = t.table("store")) config.store = read_store(*store);
  if (auto outputs = t.table("outputs")) config.outputs = read_outputs(*outputs);
  if (auto sync = t.table("sync")) config.sync = read_sync(*sync);
  if (const toml::node* links = t.find("link")) {
    const toml::array* array = links->as_array();
    // No links: `link = []`, as to_toml() writes it; toml++ does not count an empty array as one of tables.
    if (!array || !(array->empty() || array->is_array_of_tables())) {
      t.fail("link", "must be an array of tables: write [[link]]");
    }
    for (std::size_t i = 0; i < array->size(); ++i) {
      TomlTable link(*array->get(i)->as_table(), "link[" + std::to_string(i) + "]", source);
      config.links.push_back(read_link(link));
    }
  }
  t.finish();
  validate_links(config, source);  // links may also come from the command line: their number is checked later
  return config;
}

Config load_config(const std::filesystem::path& path) {
  // A directory opens as a stream that reads nothing, which would look like a file without links.
  if (std::error_code ec; std::filesystem::is_directory(path, ec)) {
    throw std::invalid_argument(path.string() + ": is a directory, not a configuration file");
  }
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  if (!in) throw std::invalid_argument(path.string() + ": cannot read the configuration file");
  return parse_config(text.str(), path.string());
}

void validate(const Config& config, std::string_view source) {
  if (config.links.empty()) {
    throw std::invalid_argument(source_prefix(source) +
                                "no links configured: add a [[link]] or give --link NAME=DEVICE:PROTOCOL");
  }
  validate_links(config, source);
}

void validate_links(const Config& config, std::string_view source) {
  std::set<std::string, std::less<>> names;
  for (std::size_t i = 0; i < config.links.size(); ++i) {
    const LinkConfig& link = config.links[i];
    const std::string which = source_prefix(source) + "link[" + std::to_string(i) + "] ('" + link.name + "')";
    // Names become store link names, and XBee radios get "<name>/<address>": keep them plain.
    const bool plain = !link.name.empty() && std::all_of(link.name.begin(), link.name.end(), [](char c) {
      return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
    });
    if (!plain) throw std::invalid_argument(which + ": 'name' must be letters, digits, '_', '-' or '.'");
    if (!names.insert(link.name).second) throw std::invalid_argument(which + ": the name is used twice");
    try {
      check_baud(link.baud);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(which + ": " + e.what());
    }
    if (link.reconnect_min > link.reconnect_max) {
      throw std::invalid_argument(which + ": reconnect_min_ms is above reconnect_max_ms");
    }
    if ((link.imu || link.imu_id) && link.format != protocol::WireFormat::mavlink) {
      throw std::invalid_argument(which + ": 'imu' and 'imu_id' are for MAVLink links");
    }
    if (!link.request_rates.empty() && link.format != protocol::WireFormat::mavlink) {
      throw std::invalid_argument(which + ": 'request_rates' is for MAVLink links");
    }
    if (link.imu_id && link.imu && *link.imu != "HIGHRES_IMU" && *link.imu != "RAW_IMU") {
      throw std::invalid_argument(which + ": 'imu_id' is for HIGHRES_IMU and RAW_IMU (" + *link.imu +
                                  " has no id field)");
    }
    try {
      VehicleFeedback check(link.format, link.feedback);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(which + ": feedback: " + e.what());
    }
  }
}

std::string to_toml(const Config& config) {
  toml::table root;
  root.insert("log_level", config.log_level);
  if (config.log_file) root.insert("log_file", config.log_file->string());
  root.insert("stats_interval_s", static_cast<std::int64_t>(config.stats_interval.count()));
  if (config.params) root.insert("params", config.params->string());

  const StoreConfig& s = config.store;
  root.insert("store", toml::table{{"path", s.path.string()},
                                   {"commit_interval_ms", static_cast<std::int64_t>(s.commit_interval.count())},
                                   {"max_size_mib", static_cast<double>(s.max_size_bytes) / kMiB},
                                   {"min_free_mib", static_cast<double>(s.min_free_bytes) / kMiB},
                                   {"on_full", s.on_full == StoreConfig::OnFull::rotate ? "rotate" : "stop"}});

  const auto endpoint_texts = [](const std::vector<Endpoint>& endpoints) {
    toml::array texts;
    for (const auto& e : endpoints) texts.push_back(e.text);
    return texts;
  };
  toml::table outputs{{"line_streams", endpoint_texts(config.outputs.line_streams)},
                      {"decimation", static_cast<std::int64_t>(config.outputs.decimation)}};
  if (config.outputs.plotjuggler) outputs.insert("plotjuggler", config.outputs.plotjuggler->text);
  if (const auto& m = config.outputs.mqtt) {
    toml::table mqtt{{"url", m->url},
                     {"station", m->station},
                     {"qos", static_cast<std::int64_t>(m->qos)},
                     {"sample_hz", m->sample_hz},
                     {"keepalive_s", static_cast<std::int64_t>(m->keepalive.count())},
                     {"reconnect_min_s", static_cast<std::int64_t>(m->reconnect_min.count())},
                     {"reconnect_max_s", static_cast<std::int64_t>(m->reconnect_max.count())},
                     {"outbox", static_cast<std::int64_t>(m->outbox)},
                     {"client_id", m->client_id},
                     {"protocol_version", m->protocol_version == 5 ? "5" : "3.1.1"}};
    if (m->estimate_hz) mqtt.insert("estimate_hz", *m->estimate_hz);
    if (m->username) mqtt.insert("username", *m->username);
    if (m->password_file) mqtt.insert("password_file", m->password_file->string());
    if (m->password_env) mqtt.insert("password_env", *m->password_env);
    if (m->ca_file) mqtt.insert("ca_file", m->ca_file->string());
    outputs.insert("mqtt", std::move(mqtt));
  }
  if (const auto& f = config.outputs.foxglove) {
    toml::table foxglove{{"listen", f->listen.text},
                         {"queue", static_cast<std::int64_t>(f->queue)},
                         {"client_queue_kib", static_cast<std::int64_t>(f->client_queue_bytes / 1024)}};
    if (f->sample_hz) foxglove.insert("sample_hz", *f->sample_hz);
    if (f->estimate_hz) foxglove.insert("estimate_hz", *f->estimate_hz);
    outputs.insert("foxglove", std::move(foxglove));
  }
  root.insert("outputs", std::move(outputs));
  if (const auto& y = config.sync) {
    toml::table sync{
        {"to", y->to}, {"interval_s", static_cast<std::int64_t>(y->interval.count())}, {"chunks", y->chunks}};
    if (!y->station.empty()) sync.insert("station", y->station);
    if (y->password_file) sync.insert("password_file", y->password_file->string());
    if (y->password_env) sync.insert("password_env", *y->password_env);
    root.insert("sync", std::move(sync));
  }

  toml::array links;
  for (const LinkConfig& l : config.links) {
    toml::table link{
        {"name", l.name},
        {"protocol", std::string(protocol::wire_format_name(l.format))},
        {"baud", static_cast<std::int64_t>(l.baud)},
        {"axes", l.axes},
        {"reconnect_min_ms", static_cast<std::int64_t>(l.reconnect_min.count())},
        {"reconnect_max_ms", static_cast<std::int64_t>(l.reconnect_max.count())},
        {"bridge", endpoint_texts(l.bridge)},
        {"calibration", to_toml_table(pipeline::calibration_to_json(l.calibration))},
        {"feedback", toml::table{{"enabled", l.feedback.enabled},
                                 {"rate_hz", l.feedback.rate_hz},
                                 {"xbee_destination64", protocol::hex(l.feedback.xbee_destination64, 8)}}}};
    if (l.imu) link.insert("imu", *l.imu);
    if (l.imu_id) link.insert("imu_id", static_cast<std::int64_t>(*l.imu_id));
    if (!l.request_rates.empty()) {
      toml::table rates;
      for (const auto& [name, hz] : l.request_rates) rates.insert(name, hz);
      link.insert("request_rates", std::move(rates));
      link.insert("gcs_sysid", static_cast<std::int64_t>(l.gcs_sysid));
      link.insert("gcs_compid", static_cast<std::int64_t>(l.gcs_compid));
    }
    if (l.device.usb_vid) {
      toml::table usb{{"vid", static_cast<std::int64_t>(*l.device.usb_vid)},
                      {"pid", static_cast<std::int64_t>(*l.device.usb_pid)}};
      if (l.device.usb_serial) usb.insert("serial", *l.device.usb_serial);
      link.insert("usb", std::move(usb));
    } else {
      link.insert("device", l.device.path.string());
    }
    links.push_back(std::move(link));
  }
  root.insert("link", std::move(links));
  std::ostringstream out;
  out << root;
  return out.str();
}

std::optional<std::uint32_t> mavlink_imu_msgid(std::string_view name) {
  static constexpr std::array<std::pair<std::string_view, std::uint32_t>, 5> kImus{
      {{"HIGHRES_IMU", 105}, {"SCALED_IMU", 26}, {"SCALED_IMU2", 116}, {"SCALED_IMU3", 129}, {"RAW_IMU", 27}}};
  for (const auto& [imu, msgid] : kImus) {
    if (imu == name) return msgid;
  }
  return std::nullopt;
}

std::optional<std::uint32_t> mavlink_message_id(std::string_view name) {
  for (const protocol::mavlink::MessageSpec& spec : protocol::mavlink::message_specs()) {
    if (spec.name == name) return spec.id;
  }
  return std::nullopt;
}

std::optional<pipeline::MavlinkImuLock> mavlink_imu_lock(const LinkConfig& link) {
  if (link.format != protocol::WireFormat::mavlink) return std::nullopt;
  pipeline::MavlinkImuLock lock{.id = link.imu_id};
  if (link.imu) lock.msgid = mavlink_imu_msgid(*link.imu);
  return lock;
}

void check_baud(std::int64_t baud) {
  // Boost.Asio's serial_port_base::baud_rate maps exactly these to termios B* constants on Linux.
  static constexpr std::array<std::int64_t, 28> kRates{50,     75,      110,     134,     150,     200,     300,
                                                       600,    1200,    1800,    2400,    4800,    9600,    19200,
                                                       38400,  57600,   115200,  230400,  460800,  500000,  576000,
                                                       921600, 1000000, 1152000, 2000000, 3000000, 3500000, 4000000};
  if (std::find(kRates.begin(), kRates.end(), baud) != kRates.end()) return;
  std::string rates;
  for (const std::int64_t rate : kRates) rates += (rates.empty() ? "" : ", ") + std::to_string(rate);
  throw std::invalid_argument("baud rate " + std::to_string(baud) + " is not one a serial port can be set to (" +
                              rates + ")");
}

}  // namespace imubridge::daemon
