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

#include "daemon/endpoint.hpp"
#include "daemon/vehicle_feedback.hpp"
#include "estimator/edit_distance.hpp"
#include "estimator/imu_axes.hpp"
#include "pipeline/session_config.hpp"
#include "protocol/hex.hpp"

namespace imubridge::daemon {
namespace {

using estimator::edit_distance;
using nlohmann::json;
constexpr double kMiB = 1024.0 * 1024.0;

// The known key a typo most likely meant: one containing the other ("baudrate" -> "baud"), else the nearest within
// a third of its length.
std::optional<std::string> closest_key(std::string_view typed, const std::vector<std::string>& known) {
  for (const auto& k : known) {
    if (typed.find(k) != std::string_view::npos || k.find(typed) != std::string::npos) return k;
  }
  std::optional<std::string> best;
  std::size_t best_distance = std::max<std::size_t>(1, typed.size() / 3) + 1;
  for (const auto& k : known) {
    if (const std::size_t d = edit_distance(typed, k); d < best_distance) best = k, best_distance = d;
  }
  return best;
}

// A TOML value as JSON: for the calibration, whose layout is pipeline::calibration_to_json's.
json toml_to_json(const toml::node& node) {
  if (const auto* t = node.as_table()) {
    json j = json::object();
    for (const auto& [k, v] : *t) j[std::string(k.str())] = toml_to_json(v);
    return j;
  }
  if (const auto* a = node.as_array()) {
    json j = json::array();
    for (const auto& v : *a) j.push_back(toml_to_json(v));
    return j;
  }
  if (const auto* i = node.as_integer()) return i->get();
  if (const auto* f = node.as_floating_point()) return f->get();
  if (const auto* b = node.as_boolean()) return b->get();
  if (const auto* s = node.as_string()) return s->get();
  return nullptr;  // dates and times: no key takes one, and null fails every check
}

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

// One TOML table being read. Every key asked for counts as known, whether present or not; finish() then names the
// first key nobody asked for. Messages read "<source>:<line>: '<path>' <what>".
class Table {
 public:
  Table(const toml::table& table, std::string path, std::string_view source)
      : table_(table), path_(std::move(path)), source_(source) {}

  [[noreturn]] void fail(std::string_view key, const std::string& what) const {
    const toml::node* node = key.empty() ? nullptr : table_.get(key);
    const auto& where = node ? node->source() : table_.source();
    throw std::invalid_argument(std::string(source_) + ":" + std::to_string(where.begin.line) + ": '" + path_of(key) +
                                "' " + what);
  }
  std::string path_of(std::string_view key) const {
    if (key.empty()) return path_;
    return path_.empty() ? std::string(key) : path_ + "." + std::string(key);
  }

  const toml::node* find(std::string_view key) {
    known_.emplace_back(key);
    return table_.get(key);
  }

  std::optional<std::int64_t> integer(std::string_view key, std::int64_t min, std::int64_t max) {
    const toml::node* node = find(key);
    if (!node) return std::nullopt;
    const auto* value = node->as_integer();
    if (!value || value->get() < min || value->get() > max) {
      fail(key, "must be an integer from " + std::to_string(min) + " to " + std::to_string(max));
    }
    return value->get();
  }
  std::optional<double> number(std::string_view key, double min, double max) {
    const toml::node* node = find(key);
    if (!node) return std::nullopt;
    const std::optional<double> value = node->is_number() ? node->value<double>() : std::nullopt;
    if (!value || !(*value >= min && *value <= max)) {
      std::ostringstream range;
      range << "must be a number from " << min << " to " << max;
      fail(key, range.str());
    }
    return value;
  }
  std::optional<std::string> string(std::string_view key) {
    const toml::node* node = find(key);
    if (!node) return std::nullopt;
    if (!node->is_string()) fail(key, "must be a string");
    return node->value<std::string>();
  }
  std::optional<bool> boolean(std::string_view key) {
    const toml::node* node = find(key);
    if (!node) return std::nullopt;
    if (!node->is_boolean()) fail(key, "must be true or false");
    return node->value<bool>();
  }
  std::optional<Table> table(std::string_view key) {
    const toml::node* node = find(key);
    if (!node) return std::nullopt;
    if (!node->is_table()) fail(key, "must be a table");
    return Table(*node->as_table(), path_of(key), source_);
  }
  std::vector<std::string> strings(std::string_view key) {
    const toml::node* node = find(key);
    if (!node) return {};
    std::vector<std::string> out;
    const auto* array = node->as_array();
    if (array) {
      for (const auto& v : *array) {
        if (!v.is_string()) break;
        out.push_back(*v.value<std::string>());
      }
    }
    if (!array || out.size() != array->size()) fail(key, "must be an array of strings");
    return out;
  }
  std::optional<Endpoint> endpoint(std::string_view key) {
    const auto text = string(key);
    if (!text) return std::nullopt;
    return parse(key, *text);
  }
  std::vector<Endpoint> endpoints(std::string_view key) {
    std::vector<Endpoint> out;
    for (const auto& text : strings(key)) out.push_back(parse(key, text));
    return out;
  }
  template <typename Enum>
  std::optional<Enum> choice(std::string_view key, const std::vector<std::pair<std::string, Enum>>& options) {
    const auto text = string(key);
    if (!text) return std::nullopt;
    std::string names;
    for (const auto& [name, value] : options) {
      if (name == *text) return value;
      names += (names.empty() ? "'" : ", '") + name + "'";
    }
    fail(key, "must be one of " + names);
  }

  void finish() const {
    for (const auto& [k, v] : table_) {
      const std::string_view key = k.str();
      if (std::find(known_.begin(), known_.end(), key) != known_.end()) continue;
      std::string message =
          std::string(source_) + ":" + std::to_string(k.source().begin.line) + ": unknown key '" + path_of(key) + "'";
      if (auto guess = closest_key(key, known_)) message += " (did you mean '" + *guess + "'?)";
      throw std::invalid_argument(message);
    }
  }

  const toml::table& raw() const { return table_; }
  std::string_view source() const { return source_; }

 private:
  Endpoint parse(std::string_view key, const std::string& text) const {
    try {
      return parse_endpoint(text);
    } catch (const std::invalid_argument& e) {
      fail(key, e.what());
    }
  }

  const toml::table& table_;
  std::string path_;
  std::string_view source_;
  std::vector<std::string> known_;
};

void read_ms(Table& t, std::string_view key, std::chrono::milliseconds& out, std::int64_t min, std::int64_t max) {
  if (auto ms = t.integer(key, min, max)) out = std::chrono::milliseconds(*ms);
}

std::uint64_t parse_hex(std::string_view text, int max_digits) {
  std::uint64_t value = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value, 16);
  if (text.empty() || text.size() > static_cast<std::size_t>(max_digits) || ec != std::errc() ||
      end != text.data() + text.size()) {
    throw std::invalid_argument("'" + std::string(text) + "' is not a hex number of at most " +
                                std::to_string(max_digits) + " digits");
  }
  return value;
}

// Unknown keys of a calibration table are reported like any other: its layout is the reference board's JSON.
void check_keys(const Table& table, const json& known) {
  Table check = table;
  for (const auto& [key, value] : known.items()) {
    const toml::node* node = check.find(key);
    if (node && value.is_object()) {
      if (!node->is_table()) check.fail(key, "must be a table");
      check_keys(Table(*node->as_table(), check.path_of(key), check.source()), value);
    }
  }
  check.finish();
}

protocol::Calibration read_calibration(Table& link) {
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

DeviceSelector read_device(Table& link) {
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

LinkConfig read_link(Table& t) {
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
  link.bridge = t.endpoints("bridge");
  if (auto feedback = t.table("feedback")) {
    link.feedback.enabled = feedback->boolean("enabled").value_or(true);
    link.feedback.rate_hz = feedback->number("rate_hz", 0.01, 1000).value_or(link.feedback.rate_hz);
    if (auto destination = feedback->string("xbee_destination64")) {
      try {
        link.feedback.xbee_destination64 = parse_hex(*destination, 16);
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

StoreConfig read_store(Table& t) {
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

OutputsConfig read_outputs(Table& t) {
  OutputsConfig outputs;
  outputs.plotjuggler = t.endpoint("plotjuggler");
  outputs.line_streams = t.endpoints("line_streams");
  if (auto n = t.integer("decimation", 1, 1'000'000)) outputs.decimation = static_cast<std::uint32_t>(*n);
  t.finish();
  return outputs;
}

bool is_wire_format(std::string_view text) {
  try {
    protocol::parse_wire_format(text);
    return true;
  } catch (const std::invalid_argument&) {
    return false;
  }
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
  Table t(root, "", source);
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
  if (const toml::node* links = t.find("link")) {
    const toml::array* array = links->as_array();
    // No links: `link = []`, as to_toml() writes it; toml++ does not count an empty array as one of tables.
    if (!array || !(array->empty() || array->is_array_of_tables())) {
      t.fail("link", "must be an array of tables: write [[link]]");
    }
    for (std::size_t i = 0; i < array->size(); ++i) {
      Table link(*array->get(i)->as_table(), "link[" + std::to_string(i) + "]", source);
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
  root.insert("outputs", std::move(outputs));

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

LinkSpec parse_link_spec(std::string_view spec) {
  const auto fail = [spec](const std::string& what) {
    return std::invalid_argument("--link '" + std::string(spec) + "': " + what +
                                 " (expected NAME=DEVICE:PROTOCOL[:BAUD], DEVICE a path or usb:VID:PID[:SERIAL])");
  };
  const auto equals = spec.find('=');
  if (equals == std::string_view::npos || equals == 0) throw fail("no NAME=");
  LinkSpec link;
  link.name = spec.substr(0, equals);
  std::vector<std::string_view> fields;  // DEVICE may hold colons itself: read PROTOCOL and BAUD from the right
  for (std::string_view rest = spec.substr(equals + 1);;) {
    const auto colon = rest.find(':');
    fields.push_back(rest.substr(0, colon));
    if (colon == std::string_view::npos) break;
    rest = rest.substr(colon + 1);
  }
  // The last field is BAUD when it is not a protocol but the one before is, or when it is all digits: so "-5" or
  // "1e8" after a protocol is a bad baud rate, not an unknown protocol.
  const std::string_view last = fields.back();
  const bool all_digits =
      !last.empty() && std::all_of(last.begin(), last.end(), [](char c) { return c >= '0' && c <= '9'; });
  if (fields.size() >= 3 && !is_wire_format(last) && (all_digits || is_wire_format(fields[fields.size() - 2]))) {
    std::int64_t baud = 0;
    const auto [end, ec] = std::from_chars(last.data(), last.data() + last.size(), baud);
    if (last.empty() || ec != std::errc() || end != last.data() + last.size()) {
      throw fail("baud rate '" + std::string(last) + "' is not a whole number");
    }
    try {
      check_baud(baud);
    } catch (const std::invalid_argument& e) {
      throw fail(e.what());
    }
    link.baud = static_cast<std::uint32_t>(baud);
    fields.pop_back();
  }
  if (fields.size() < 2) throw fail("no PROTOCOL");
  try {
    link.format = protocol::parse_wire_format(fields.back());
  } catch (const std::invalid_argument& e) {
    throw fail(e.what());
  }
  fields.pop_back();
  if (fields.front() == "usb") {
    if (fields.size() != 3 && fields.size() != 4) throw fail("usb:VID:PID[:SERIAL] expected");
    try {
      link.device.usb_vid = static_cast<std::uint16_t>(parse_hex(fields[1], 4));
      link.device.usb_pid = static_cast<std::uint16_t>(parse_hex(fields[2], 4));
    } catch (const std::invalid_argument& e) {
      throw fail(e.what());
    }
    if (fields.size() == 4) link.device.usb_serial = std::string(fields[3]);
  } else {
    std::string path;
    for (const auto& f : fields) path += (path.empty() ? "" : ":") + std::string(f);
    if (path.empty()) throw fail("no DEVICE");
    link.device.path = path;
  }
  return link;
}

void apply_link_spec(Config& config, const LinkSpec& spec) {
  auto it =
      std::find_if(config.links.begin(), config.links.end(), [&](const LinkConfig& l) { return l.name == spec.name; });
  if (it == config.links.end()) {
    it = config.links.emplace(config.links.end());
    it->name = spec.name;
  }
  it->device = spec.device;
  it->format = spec.format;
  if (spec.baud) it->baud = *spec.baud;
}

}  // namespace imubridge::daemon
