#include "daemon/config_file.hpp"

#include <toml++/toml.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <stdexcept>

#include "archive/pg_connection.hpp"
#include "daemon/config_table.hpp"
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

// Codecs of the keys whose values are more than a number or a string. Generic ones: daemon/config_table.hpp.

Endpoint parse_endpoint_at(const TomlTable& t, std::string_view key, const std::string& text) {
  try {
    return parse_endpoint(text);
  } catch (const std::invalid_argument& e) {
    t.fail(key, e.what());
  }
}

// An endpoint as written ("udp://127.0.0.1:9870"), which its text keeps.
struct EndpointText {
  std::optional<Endpoint> read(TomlTable& t, std::string_view key) const {
    const auto text = t.string(key);
    if (!text) return std::nullopt;
    return parse_endpoint_at(t, key, *text);
  }
  std::string write(const Endpoint& endpoint) const { return endpoint.text; }
};

// An array of endpoints, written even when empty.
struct EndpointTexts {
  std::optional<std::vector<Endpoint>> read(TomlTable& t, std::string_view key) const {
    std::vector<Endpoint> out;
    for (const auto& text : t.strings(key)) out.push_back(parse_endpoint_at(t, key, text));
    return out;
  }
  toml::array write(const std::vector<Endpoint>& endpoints) const {
    toml::array texts;
    for (const auto& e : endpoints) texts.push_back(e.text);
    return texts;
  }
};

// A TCP address to listen on, written without a scheme ("127.0.0.1:8765").
struct ListenAddress {
  std::optional<Endpoint> read(TomlTable& t, std::string_view key) const {
    const auto text = t.string(key);
    if (!text) return std::nullopt;
    Endpoint listen = parse_endpoint_at(t, key, "tcp-listen://" + *text);
    listen.text = *text;
    return listen;
  }
  std::string write(const Endpoint& endpoint) const { return endpoint.text; }
};

// A number of MiB held as bytes.
struct Mebibytes {
  double max;
  bool zero_or_at_least_one = false;  // a size cap: below a fresh database's size every check would rotate again
  std::optional<std::uint64_t> read(TomlTable& t, std::string_view key) const {
    const auto mib = t.number(key, 0, max);
    if (!mib) return std::nullopt;
    if (zero_or_at_least_one && *mib > 0 && *mib < 1) t.fail(key, "must be 0 (no cap) or at least 1");
    return std::llround(*mib * kMiB);
  }
  double write(std::uint64_t bytes) const { return static_cast<double>(bytes) / kMiB; }
};

// A whole number of KiB held as bytes.
struct Kibibytes {
  std::int64_t min, max;
  std::optional<std::size_t> read(TomlTable& t, std::string_view key) const {
    if (auto kib = t.integer(key, min, max)) return static_cast<std::size_t>(*kib) * 1024;
    return std::nullopt;
  }
  std::int64_t write(std::size_t bytes) const { return static_cast<std::int64_t>(bytes / 1024); }
};

struct WireFormatName {
  std::optional<protocol::WireFormat> read(TomlTable& t, std::string_view key) const {
    const auto name = t.string(key);
    if (!name) return std::nullopt;
    try {
      return protocol::parse_wire_format(*name);
    } catch (const std::invalid_argument& e) {
      t.fail(key, e.what());
    }
  }
  std::string write(protocol::WireFormat format) const { return std::string(protocol::wire_format_name(format)); }
};

struct BaudRate {
  std::optional<std::uint32_t> read(TomlTable& t, std::string_view key) const {
    const toml::node* baud = t.find(key);
    if (!baud) return std::nullopt;
    const auto* rate = baud->as_integer();
    if (!rate) t.fail(key, "must be a whole number of bits per second, e.g. 115200");
    try {
      check_baud(rate->get());
    } catch (const std::invalid_argument& e) {
      t.fail(key, e.what());
    }
    return static_cast<std::uint32_t>(rate->get());
  }
  std::int64_t write(std::uint32_t baud) const { return baud; }
};

// Kept as written; estimator::parse_imu_axes() reads it when the link starts.
struct ImuAxesText {
  std::optional<std::string> read(TomlTable& t, std::string_view key) const {
    auto axes = t.string(key);
    if (!axes) return std::nullopt;
    try {
      estimator::parse_imu_axes(*axes);
    } catch (const std::invalid_argument& e) {
      t.fail(key, e.what());
    }
    return axes;
  }
  std::string write(const std::string& axes) const { return axes; }
};

struct ImuMessageName {
  std::optional<std::string> read(TomlTable& t, std::string_view key) const {
    auto imu = t.string(key);
    if (imu && !mavlink_imu_msgid(*imu)) {
      t.fail(key, "must be one of 'HIGHRES_IMU', 'SCALED_IMU', 'SCALED_IMU2', 'SCALED_IMU3', 'RAW_IMU'");
    }
    return imu;
  }
  std::string write(const std::string& imu) const { return imu; }
};

// A 64-bit XBee address as 16 hex digits (a string: TOML integers are signed).
struct HexAddress {
  std::optional<std::uint64_t> read(TomlTable& t, std::string_view key) const {
    const auto text = t.string(key);
    if (!text) return std::nullopt;
    try {
      return protocol::parse_hex(*text, 16);
    } catch (const std::invalid_argument& e) {
      t.fail(key, e.what());
    }
  }
  std::string write(std::uint64_t address) const { return protocol::hex(address, 8); }
};

// A table laid out as the reference board's calibration JSON; keys left out keep the reference board's values.
// Unknown keys are reported like any other.
struct CalibrationTable {
  std::optional<protocol::Calibration> read(TomlTable& link, std::string_view key) const {
    auto table = link.table(key);
    if (!table) return std::nullopt;
    json calibration = pipeline::calibration_to_json(protocol::Calibration::reference_board());
    check_keys(*table, calibration);
    calibration.merge_patch(toml_to_json(table->raw()));
    try {
      return pipeline::calibration_from_json(calibration);
    } catch (const std::exception& e) {  // a wrongly typed value, or not a valid calibration
      link.fail(key, std::string("is not usable: ") + e.what());
    }
  }
  toml::table write(const protocol::Calibration& calibration) const {
    return to_toml_table(pipeline::calibration_to_json(calibration));
  }
  // Calibration has no ==; its JSON holds every value.
  void compare(const protocol::Calibration& a, const protocol::Calibration& b, const std::string& path,
               const KeyVisitor& visit) const {
    const json first = pipeline::calibration_to_json(a);
    visit(path, first == pipeline::calibration_to_json(b),
          first == pipeline::calibration_to_json(protocol::Calibration::reference_board()));
  }
};

// MAVLink message name -> Hz.
struct RequestRates {
  std::optional<std::map<std::string, double>> read(TomlTable& link, std::string_view key) const {
    auto rates = link.table(key);
    if (!rates) return std::nullopt;
    std::map<std::string, double> out;
    for (const auto& [message, value] : rates->raw()) {
      const std::string name(message.str());
      if (!mavlink_message_id(name)) rates->fail(name, "is not a MAVLink message name (e.g. HIGHRES_IMU, ATTITUDE)");
      out[name] = *rates->number(name, 0.1, 2000);
    }
    rates->finish();
    return out;
  }
  toml::table write(const std::map<std::string, double>& rates) const {
    toml::table out;
    for (const auto& [name, hz] : rates) out.insert(name, hz);
    return out;
  }
};

// A link's device is one of two keys: 'device' (a path) or 'usb' (vid, pid and maybe serial).
void read_device_selector(TomlTable& link, LinkConfig& out) {
  DeviceSelector& device = out.device;
  const auto path = link.string("device");
  auto usb = link.table("usb");
  if (path.has_value() == usb.has_value()) link.fail("", "needs exactly one of 'device' (a path) and 'usb'");
  if (path) {
    if (path->empty()) link.fail("device", "must not be empty");
    device.path = *path;
    return;
  }
  const auto vid = usb->integer("vid", 0, 0xFFFF);
  const auto pid = usb->integer("pid", 0, 0xFFFF);
  if (!vid || !pid) usb->fail("", "needs 'vid' and 'pid' (e.g. vid = 0x0403, pid = 0x6001)");
  device.usb_vid = static_cast<std::uint16_t>(*vid);
  device.usb_pid = static_cast<std::uint16_t>(*pid);
  device.usb_serial = usb->string("serial");
  usb->finish();
}
void write_device_selector(const LinkConfig& in, toml::table& link) {
  const DeviceSelector& device = in.device;
  if (!device.usb_vid) {
    link.insert("device", device.path.string());
    return;
  }
  toml::table usb{{"vid", static_cast<std::int64_t>(*device.usb_vid)},
                  {"pid", static_cast<std::int64_t>(*device.usb_pid)}};
  if (device.usb_serial) usb.insert("serial", *device.usb_serial);
  link.insert("usb", std::move(usb));
}

// mqtt://HOST[:PORT] or mqtts://HOST[:PORT], from the url already read. Unlike an endpoint's, the host may be a name:
// libmosquitto resolves it on its own thread, so a slow DNS never holds up recording.
void set_broker_address(TomlTable& t, MqttConfig& mqtt) {
  const auto bad = [&](const std::string& why) {
    t.fail("url", "'" + mqtt.url + "': " + why + " (expected mqtt://HOST[:PORT] or mqtts://HOST[:PORT])");
  };
  std::string_view rest = mqtt.url;
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
  mqtt.host = host;
}

// Link names and MQTT stations: a link's name becomes a store link name and, on an XBee link, "<name>/<address>"; a
// station is a topic level, where '/' would add a level and '+', '#' are wildcards.
bool is_plain_name(std::string_view name) {
  return !name.empty() && std::all_of(name.begin(), name.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
  });
}

// [outputs.mqtt] and [sync] name where to read a password, from one source.
template <typename Struct>
void one_password_source(TomlTable& t, Struct& config) {
  if (config.password_file && config.password_env) t.fail("password_env", "and password_file: give one of them");
}

// Rules across keys, each run after the key of its row is read.

void check_station(TomlTable& t, MqttConfig& mqtt) {
  if (!is_plain_name(mqtt.station)) t.fail("station", "must be letters, digits, '_', '-' or '.' (it is a topic level)");
}
void check_reconnect_order(TomlTable& t, MqttConfig& mqtt) {
  if (mqtt.reconnect_min > mqtt.reconnect_max) t.fail("reconnect_min_s", "is above reconnect_max_s");
}
void check_broker_password(TomlTable& t, MqttConfig& mqtt) {
  one_password_source(t, mqtt);
  if ((mqtt.password_file || mqtt.password_env) && !mqtt.username) {
    t.fail(mqtt.password_file ? "password_file" : "password_env", "needs a 'username'");
  }
}
void check_ca_file(TomlTable& t, MqttConfig& mqtt) {
  if (mqtt.ca_file && !mqtt.tls) t.fail("ca_file", "is for mqtts:// URLs");
}
// The key itself may not be "", so empty means absent.
void default_client_id(TomlTable&, MqttConfig& mqtt) {
  if (mqtt.client_id.empty()) mqtt.client_id = "imubridge-" + mqtt.station;
}

// The tables of keys, one row per key, in the order keys are read (the order mistakes are found in).

KeyTable<MqttConfig> mqtt_keys() {
  using M = MqttConfig;
  using std::chrono::seconds;
  return {
      key("url", &M::url, Text<>{},
          {.required = "needs a 'url' (mqtt://HOST[:PORT] or mqtts://HOST[:PORT])", .then = set_broker_address}),
      key("station", &M::station, Text<>{},
          {.required = "needs a 'station': this ground station's name in the topics, e.g. \"field-1\"",
           .then = check_station}),
      key("qos", &M::qos, Integer<int>{0, 1}),
      key("sample_hz", &M::sample_hz, Number{0, 100'000}),
      key("estimate_hz", &M::estimate_hz, Number{0, 100'000}),
      key("keepalive_s", &M::keepalive, WholeDuration<seconds>{5, 65'535}),  // libmosquitto's range
      key("reconnect_min_s", &M::reconnect_min, WholeDuration<seconds>{1, 3600}),
      key("reconnect_max_s", &M::reconnect_max, WholeDuration<seconds>{1, 3600}, {.then = check_reconnect_order}),
      key("outbox", &M::outbox, Integer<std::size_t>{16, 10'000'000}),
      key("username", &M::username, Text<>{}),
      refused_key<M>("password", "is never written in the configuration: use password_file or password_env"),
      key("password_file", &M::password_file, PathText{}),
      key("password_env", &M::password_env, Text<>{}, {.then = check_broker_password}),
      key("ca_file", &M::ca_file, PathText{}, {.then = check_ca_file}),
      key("client_id", &M::client_id, Text<>{.non_empty = true}, {.then = default_client_id}),
      key("protocol_version", &M::protocol_version, Choice<int>{{{"3.1.1", 4}, {"5", 5}}}),
  };
}

KeyTable<FoxgloveConfig> foxglove_keys() {
  using F = FoxgloveConfig;
  return {
      key("listen", &F::listen, ListenAddress{}),
      key("sample_hz", &F::sample_hz, Number{0, 100'000}),
      key("estimate_hz", &F::estimate_hz, Number{0, 100'000}),
      key("queue", &F::queue, Integer<std::size_t>{16, 10'000'000}),
      key("client_queue_kib", &F::client_queue_bytes, Kibibytes{16, 1'048'576}),
  };
}

KeyTable<OutputsConfig> outputs_keys() {
  using O = OutputsConfig;
  return {
      key("plotjuggler", &O::plotjuggler, EndpointText{}),
      key("line_streams", &O::line_streams, EndpointTexts{}),
      key("decimation", &O::decimation, Integer<std::uint32_t>{1, 1'000'000}),
      key("mqtt", &O::mqtt, Table<MqttConfig>{mqtt_keys()}),
      key("foxglove", &O::foxglove, Table<FoxgloveConfig>{foxglove_keys()}),
  };
}

KeyTable<StoreConfig> store_keys() {
  using S = StoreConfig;
  return {
      key("path", &S::path, PathText{}),
      key("commit_interval_ms", &S::commit_interval, WholeDuration<std::chrono::milliseconds>{1, 60'000}),
      key("max_size_mib", &S::max_size_bytes, Mebibytes{.max = 1e9, .zero_or_at_least_one = true}),
      key("min_free_mib", &S::min_free_bytes, Mebibytes{.max = 1e9}),
      key("on_full", &S::on_full, Choice<S::OnFull>{{{"rotate", S::OnFull::rotate}, {"stop", S::OnFull::stop}}}),
  };
}

void check_archive_scheme(TomlTable& t, SyncConfig& sync) {
  if (!sync.to.starts_with("postgresql://") && !sync.to.starts_with("postgres://")) {
    t.fail("to", "must be a postgresql:// URL");
  }
}
// The archive's URL holds no password, and neither does a 'password' key: the configuration is recorded with every
// session. The row of 'password', read after 'to'.
void refuse_archive_password(TomlTable& t, SyncConfig& sync) {
  const char* why = "holds a password, which is never written in the configuration: use password_file or password_env";
  if (t.find("password")) t.fail("password", why);
  if (archive::redact_url(sync.to) != sync.to) t.fail("to", why);
}
// Empty: the host's name, found when syncing.
bool has_station(const SyncConfig& sync) { return !sync.station.empty(); }

KeyTable<SyncConfig> sync_keys() {
  using S = SyncConfig;
  return {
      key("to", &S::to, Text<>{},
          {.required = "needs 'to', the archive's URL: postgresql://USER@HOST[:PORT]/DATABASE",
           .then = check_archive_scheme}),
      {.name = "password", .read = refuse_archive_password},
      key("station", &S::station, Text<>{}, {.written = has_station}),
      key("interval_s", &S::interval, WholeDuration<std::chrono::seconds>{1, 86'400}),
      key("chunks", &S::chunks, Flag{}),
      key("password_file", &S::password_file, PathText{}),
      key("password_env", &S::password_env, Text<>{}, {.then = one_password_source<S>}),
  };
}

KeyTable<VehicleFeedbackConfig> feedback_keys() {
  using V = VehicleFeedbackConfig;
  return {
      key("enabled", &V::enabled, Flag{}),
      key("rate_hz", &V::rate_hz, Number{0.01, 1000}),
      key("xbee_destination64", &V::xbee_destination64, HexAddress{}),
  };
}

void check_link_named(TomlTable& t, LinkConfig& link) {
  if (link.name.empty()) t.fail("", "needs a 'name'");
}
// The GCS identity is only used to request rates, so it is written only with them.
bool requests_rates(const LinkConfig& link) { return !link.request_rates.empty(); }

KeyTable<LinkConfig> link_keys() {
  using L = LinkConfig;
  using std::chrono::milliseconds;
  return {
      key("name", &L::name, Text<>{}, {.then = check_link_named}),
      special_key("device", &L::device, read_device_selector, write_device_selector),  // or 'usb'
      key("protocol", &L::format, WireFormatName{}),
      key("baud", &L::baud, BaudRate{}),
      key("calibration", &L::calibration, CalibrationTable{}),
      key("axes", &L::axes, ImuAxesText{}),
      key("imu", &L::imu, ImuMessageName{}),
      key("imu_id", &L::imu_id, Integer<std::uint8_t>{0, 255}),
      key("request_rates", &L::request_rates, RequestRates{}, {.written = requests_rates}),
      key("gcs_sysid", &L::gcs_sysid, Integer<std::uint8_t>{1, 255}, {.written = requests_rates}),
      key("gcs_compid", &L::gcs_compid, Integer<std::uint8_t>{0, 255}, {.written = requests_rates}),
      key("bridge", &L::bridge, EndpointTexts{}),
      // A [link.feedback] table enables feedback unless it says otherwise.
      key("feedback", &L::feedback, Table<VehicleFeedbackConfig>{feedback_keys(), {.enabled = true}}),
      key("reconnect_min_ms", &L::reconnect_min, WholeDuration<milliseconds>{1, 3'600'000}),
      key("reconnect_max_ms", &L::reconnect_max, WholeDuration<milliseconds>{1, 3'600'000}),
  };
}

// Every key of the file: parse_config() reads these rows and to_toml() writes them.
const KeyTable<Config>& config_keys() {
  using C = Config;
  static const KeyTable<Config> keys{
      key("log_level", &C::log_level,
          Choice<std::string>{
              {{"trace", "trace"}, {"debug", "debug"}, {"info", "info"}, {"warn", "warn"}, {"error", "error"}}}),
      key("log_file", &C::log_file, PathText{}),
      key("stats_interval_s", &C::stats_interval, WholeDuration<std::chrono::seconds>{1, 86'400}),
      key("params", &C::params, PathText{}),
      key("store", &C::store, Table<StoreConfig>{store_keys()}),
      key("outputs", &C::outputs, Table<OutputsConfig>{outputs_keys()}),
      key("sync", &C::sync, Table<SyncConfig>{sync_keys()}),
      key("link", &C::links, TableArray<LinkConfig>{link_keys()}),
  };
  return keys;
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
  read_keys(t, config_keys(), config);
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
    if (!is_plain_name(link.name))
      throw std::invalid_argument(which + ": 'name' must be letters, digits, '_', '-' or '.'");
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
  std::ostringstream out;
  out << write_keys(config_keys(), config);
  return out.str();
}

std::vector<KeyComparison> compare_config_keys(const Config& a, const Config& b) {
  std::vector<KeyComparison> keys;
  compare_keys(config_keys(), a, b, "", [&](const std::string& path, bool equal, bool first_is_default) {
    keys.push_back({.path = path, .equal = equal, .first_is_default = first_is_default});
  });
  return keys;
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
