#include "replay/export.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <initializer_list>
#include <map>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <variant>
#include <vector>

#include "replay/mcap_writer.hpp"
#include "replay/session_lookup.hpp"

namespace imubridge::replay {
namespace {

using Value = std::variant<std::nullptr_t, std::int64_t, std::uint64_t, double, std::string_view>;

class RowWriter {
 public:
  RowWriter(ExportFormat format, std::ostream& out, std::vector<const char*> columns)
      : format_(format), out_(out), columns_(std::move(columns)) {
    if (format_ != ExportFormat::csv) return;
    for (std::size_t i = 0; i < columns_.size(); ++i) out_ << (i ? "," : "") << columns_[i];
    out_ << '\n';
  }

  void row(std::initializer_list<Value> values) {
    if (format_ == ExportFormat::jsonl) {
      nlohmann::ordered_json j;  // keeps the columns in order; dumps NaN as null
      auto name = columns_.begin();
      for (const auto& value : values) std::visit([&](auto v) { j[*name++] = v; }, value);
      out_ << j.dump() << '\n';
      return;
    }
    bool first = true;
    for (const auto& value : values) {
      if (!first) out_ << ',';
      first = false;
      std::visit([this](auto v) { csv_field(v); }, value);
    }
    out_ << '\n';
  }

 private:
  void csv_field(std::nullptr_t) {}
  void csv_field(std::int64_t v) { out_ << v; }
  void csv_field(std::uint64_t v) { out_ << v; }
  void csv_field(double v) {
    if (std::isnan(v)) return;
    char buffer[32];
    const auto end = std::to_chars(buffer, buffer + sizeof buffer, v).ptr;  // shortest text that reads back as v
    out_.write(buffer, end - buffer);
  }
  void csv_field(std::string_view v) {  // RFC 4180: quoted when it holds a separator, quote or line break
    if (v.find_first_of(",\"\r\n") == std::string_view::npos) {
      out_ << v;
      return;
    }
    out_ << '"';
    for (char c : v) out_ << (c == '"' ? "\"\"" : std::string_view(&c, 1));
    out_ << '"';
  }

  ExportFormat format_;
  std::ostream& out_;
  std::vector<const char*> columns_;
};

Value optional_real(bool present, double v) { return present ? Value(v) : Value(nullptr); }

// Session time (ExportTime::session): where each clock's zero is, from each link's first sample.
class SessionClock {
 public:
  // Throws std::invalid_argument for a session without samples: its time has no start.
  SessionClock(const store::Store& store, std::int64_t session, std::string_view remedy) {
    for (const protocol::Sample& s : store.first_samples(session)) {
      first_device_us_[s.link_id] = s.device_time_us;
      origin_mono_ns_ = first_device_us_.size() == 1 ? s.recv_mono_ns : std::min(origin_mono_ns_, s.recv_mono_ns);
    }
    if (first_device_us_.empty()) {
      throw std::invalid_argument("session " + std::to_string(session) +
                                  " has no samples, so no session time (it counts from the first sample)" +
                                  std::string(remedy));
    }
  }

  // On the IMU's clock, from the link's first sample.
  std::int64_t device_ns(std::int64_t link, std::int64_t device_time_us) const {
    return (device_time_us - first_device_us(link)) * 1000;
  }
  // An estimate's time is its sample's device time in seconds: back to whole microseconds, so that a sample and its
  // estimate have the same session time to the last digit.
  std::int64_t estimate_ns(std::int64_t link, double t_s) const {
    return device_ns(link, std::isfinite(t_s) ? std::llround(t_s * 1e6) : first_device_us(link));
  }
  // On the session's monotonic clock, from the first sample's arrival.
  std::int64_t mono_ns(std::int64_t mono) const { return mono - origin_mono_ns_; }
  std::int64_t origin_mono_ns() const { return origin_mono_ns_; }

 private:
  std::int64_t first_device_us(std::int64_t link) const {
    const auto it = first_device_us_.find(link);
    if (it == first_device_us_.end()) {
      throw std::runtime_error("link " + std::to_string(link) + " has estimates but no samples");
    }
    return it->second;
  }

  std::map<std::int64_t, std::int64_t> first_device_us_;
  std::int64_t origin_mono_ns_ = 0;
};

double seconds(std::int64_t ns) { return static_cast<double>(ns) / 1e9; }

// Without `run`, the session's only run; none when it has no runs and `runs_needed` is false.
std::optional<std::int64_t> estimates_run(const store::Store& store, std::int64_t session,
                                          std::optional<std::int64_t> run, bool runs_needed = true) {
  if (run) return find_run(store, session, *run).id;
  const auto runs = store.runs(session);
  if (runs.size() == 1) return runs.front().id;
  const std::string s = "session " + std::to_string(session);
  if (runs.empty() && !runs_needed) return std::nullopt;
  if (runs.empty()) throw std::invalid_argument(s + " has no runs yet: `imubridge replay` makes one");
  std::string known;
  for (const auto& r : runs) known += (known.empty() ? "" : ", ") + std::to_string(r.id) + " " + r.info.kind;
  throw std::invalid_argument(s + " has " + std::to_string(runs.size()) + " runs (" + known +
                              "): choose one with --run");
}

}  // namespace

ExportTable parse_export_table(std::string_view name) {
  if (name == "samples") return ExportTable::samples;
  if (name == "estimates") return ExportTable::estimates;
  if (name == "reference") return ExportTable::reference;
  if (name == "events") return ExportTable::events;
  throw std::invalid_argument("unknown table \"" + std::string(name) + "\" (samples, estimates, reference, events)");
}

ExportFormat parse_export_format(std::string_view name) {
  if (name == "csv") return ExportFormat::csv;
  if (name == "jsonl") return ExportFormat::jsonl;
  if (name == "mcap") return ExportFormat::mcap;
  throw std::invalid_argument("unknown export format \"" + std::string(name) + "\" (csv, jsonl, mcap)");
}

ExportTime parse_export_time(std::string_view name) {
  if (name == "session") return ExportTime::session;
  if (name == "recorded") return ExportTime::recorded;
  throw std::invalid_argument("unknown time \"" + std::string(name) + "\" (session, recorded)");
}

const char* describe_export_time(ExportTime time) {
  return time == ExportTime::session ? "session time (session_t_s: s since the first sample)"
                                     : "the store's clocks (device_time_us and device_t_s: the IMU's; recv_mono_ns "
                                       "and mono_ns: the session's monotonic clock; wall_ns: UTC)";
}

void export_table(const store::Store& store, std::int64_t session, ExportTable table, std::optional<std::int64_t> run,
                  ExportFormat format, ExportTime time, std::ostream& out) {
  find_session(store, session);
  if (format == ExportFormat::mcap)
    throw std::logic_error("export_table writes CSV or JSON Lines; MCAP is export_mcap");
  if (run && table != ExportTable::estimates) throw std::invalid_argument("--run selects estimates only");
  // Before any output: these may fail.
  const std::optional<std::int64_t> chosen =
      table == ExportTable::estimates ? estimates_run(store, session, run) : std::nullopt;
  std::optional<SessionClock> clock;
  if (time == ExportTime::session) clock.emplace(store, session, ": export it with --time recorded");
  const bool recorded = !clock;
  switch (table) {
    case ExportTable::samples: {
      RowWriter w(format, out,
                  recorded ? std::vector<const char*>{"link_id", "seq", "device_time_us", "recv_mono_ns", "ax", "ay",
                                                      "az", "gx", "gy", "gz", "mx", "my", "mz", "temperature_c"}
                           : std::vector<const char*>{"link_id", "seq", "session_t_s", "ax", "ay", "az", "gx", "gy",
                                                      "gz", "mx", "my", "mz", "temperature_c"});
      store.for_each_sample(session, std::nullopt, [&](const protocol::Sample& s) {
        const Value m[] = {optional_real(s.has_mag, s.mag[0]), optional_real(s.has_mag, s.mag[1]),
                           optional_real(s.has_mag, s.mag[2]), optional_real(s.has_temperature, s.temperature_c)};
        if (recorded) {
          w.row({std::int64_t{s.link_id}, s.seq, s.device_time_us, s.recv_mono_ns, s.accel[0], s.accel[1], s.accel[2],
                 s.gyro[0], s.gyro[1], s.gyro[2], m[0], m[1], m[2], m[3]});
        } else {
          w.row({std::int64_t{s.link_id}, s.seq, seconds(clock->device_ns(s.link_id, s.device_time_us)), s.accel[0],
                 s.accel[1], s.accel[2], s.gyro[0], s.gyro[1], s.gyro[2], m[0], m[1], m[2], m[3]});
        }
      });
      break;
    }
    case ExportTable::estimates: {
      RowWriter w(
          format, out,
          {"link_id", "seq", recorded ? "device_t_s" : "session_t_s", "fx", "fy", "vx", "vy", "var_vx", "var_vy"});
      store.for_each_estimate(*chosen, [&](const store::Estimate& e) {
        w.row({e.link_id, e.seq, recorded ? e.t_s : seconds(clock->estimate_ns(e.link_id, e.t_s)), e.fx, e.fy, e.vx,
               e.vy, e.var_vx, e.var_vy});
      });
      break;
    }
    case ExportTable::reference: {
      RowWriter w(format, out,
                  {recorded ? "mono_ns" : "session_t_s", "px", "py", "pz", "qw", "qx", "qy", "qz", "vx", "vy", "vz"});
      store.for_each_reference(session, [&](const store::ReferenceRow& r) {
        const auto& p = r.position;
        const auto& q = r.quat_wxyz;
        const bool has_v = r.velocity.has_value();
        const auto v = r.velocity.value_or(std::array<double, 3>{});
        w.row({recorded ? Value(r.t_ns) : Value(seconds(clock->mono_ns(r.t_ns))), p[0], p[1], p[2], q[0], q[1], q[2],
               q[3], optional_real(has_v, v[0]), optional_real(has_v, v[1]), optional_real(has_v, v[2])});
      });
      break;
    }
    case ExportTable::events: {
      RowWriter w(format, out,
                  recorded ? std::vector<const char*>{"link_id", "mono_ns", "wall_ns", "kind", "count", "detail"}
                           : std::vector<const char*>{"link_id", "session_t_s", "wall_ns", "kind", "count", "detail"});
      for (const auto& e : store.events(session)) {
        w.row({e.link_id ? Value(*e.link_id) : Value(nullptr),
               recorded ? Value(e.mono_ns) : Value(seconds(clock->mono_ns(e.mono_ns))), e.wall_ns, e.kind, e.count,
               e.detail});
      }
      break;
    }
  }
  if (!out.flush()) throw std::runtime_error("write error while exporting");
}

namespace {

// The messages' JSON schemas (draft 2020-12 subset that Foxglove and PlotJuggler read). foxglove.PoseInFrame and
// foxglove.Log follow Foxglove's published message schemas, so its 3-D and Log panels show them as they are.
constexpr std::string_view kNumber = R"({"type":["number","null"]})";

std::string object_schema(const std::vector<std::pair<std::string_view, std::string_view>>& properties) {
  std::string out = R"({"type":"object","properties":{)";
  for (std::size_t i = 0; i < properties.size(); ++i) {
    out += (i ? "," : "") + nlohmann::json(properties[i].first).dump() + ":" + std::string(properties[i].second);
  }
  return out + "}}";
}

const std::string& sample_schema() {
  static const std::string schema = object_schema({{"session_t_s", kNumber},
                                                   {"link_id", R"({"type":"integer"})"},
                                                   {"seq", R"({"type":"integer"})"},
                                                   {"device_time_us", R"({"type":"integer"})"},
                                                   {"recv_mono_ns", R"({"type":"integer"})"},
                                                   {"ax", kNumber},
                                                   {"ay", kNumber},
                                                   {"az", kNumber},
                                                   {"gx", kNumber},
                                                   {"gy", kNumber},
                                                   {"gz", kNumber},
                                                   {"mx", kNumber},
                                                   {"my", kNumber},
                                                   {"mz", kNumber},
                                                   {"temperature_c", kNumber}});
  return schema;
}

const std::string& estimate_schema() {
  static const std::string schema = object_schema({{"session_t_s", kNumber},
                                                   {"link_id", R"({"type":"integer"})"},
                                                   {"seq", R"({"type":"integer"})"},
                                                   {"device_t_s", kNumber},
                                                   {"fx", kNumber},
                                                   {"fy", kNumber},
                                                   {"vx", kNumber},
                                                   {"vy", kNumber},
                                                   {"var_vx", kNumber},
                                                   {"var_vy", kNumber}});
  return schema;
}

const std::string& velocity_schema() {
  static const std::string schema = object_schema({{"session_t_s", kNumber},
                                                   {"mono_ns", R"({"type":"integer"})"},
                                                   {"vx", kNumber},
                                                   {"vy", kNumber},
                                                   {"vz", kNumber}});
  return schema;
}

constexpr std::string_view kTimeSchema = R"({"type":"object","properties":{"sec":{"type":"integer","minimum":0},)"
                                         R"("nsec":{"type":"integer","minimum":0,"maximum":999999999}}})";

const std::string& pose_in_frame_schema() {
  static const std::string schema = [] {
    const std::string xyz = object_schema({{"x", kNumber}, {"y", kNumber}, {"z", kNumber}});
    const std::string xyzw = object_schema({{"x", kNumber}, {"y", kNumber}, {"z", kNumber}, {"w", kNumber}});
    const std::string pose = object_schema({{"position", xyz}, {"orientation", xyzw}});
    return object_schema({{"timestamp", kTimeSchema}, {"frame_id", R"({"type":"string"})"}, {"pose", pose}});
  }();
  return schema;
}

const std::string& log_schema() {
  static const std::string schema = object_schema(
      {{"timestamp", kTimeSchema},
       {"level",
        R"({"type":"integer","enum":[0,1,2,3,4,5],"description":"UNKNOWN, DEBUG, INFO, WARNING, ERROR, FATAL"})"},
       {"message", R"({"type":"string"})"},
       {"name", R"({"type":"string"})"},
       {"file", R"({"type":"string"})"},
       {"line", R"({"type":"integer","minimum":0})"}});
  return schema;
}

// foxglove.Log's levels.
constexpr int kInfo = 2, kWarning = 3;
// Events that say data was lost, damaged or left out are warnings; the rest (notes, connections, counters,
// takeoff and landing) information.
int log_level(std::string_view kind) {
  for (std::string_view warning :
       {"sequence_gap", "crc_failure", "link_lost", "interrupted", "import_damaged", "import_clipped", "import_skipped",
        "dropout", "mqtt_dropped", "mqtt_lost", "imu_axes_mismatch"}) {
    if (kind == warning) return kWarning;
  }
  return kInfo;
}

nlohmann::ordered_json time_json(std::uint64_t ns) {
  return {{"sec", ns / 1'000'000'000u}, {"nsec", ns % 1'000'000'000u}};
}

// A time on the session's monotonic clock as an MCAP timestamp: the clock counts from the machine's (or the log's)
// boot, so it is not negative; were it, the message would sort first.
std::uint64_t log_time(std::int64_t mono_ns) { return mono_ns < 0 ? 0 : static_cast<std::uint64_t>(mono_ns); }

// Text from logs (a PX4 or ArduPilot message) need not be UTF-8, which JSON must be: bad bytes become U+FFFD.
std::string json_text(const nlohmann::ordered_json& j) {
  return j.dump(-1, ' ', false, nlohmann::ordered_json::error_handler_t::replace);
}

nlohmann::ordered_json optional_number(bool present, double v) {
  return present ? nlohmann::ordered_json(v) : nlohmann::ordered_json(nullptr);
}

// Channels made when their first message comes, so a session without reference or estimates has no empty topics.
class McapChannels {
 public:
  explicit McapChannels(mcap::Writer& writer) : writer_(writer) {}

  std::uint16_t get(const std::string& topic, std::string_view schema_name, const std::string& schema,
                    const std::map<std::string, std::string>& metadata = {}) {
    if (const auto it = channels_.find(topic); it != channels_.end()) return it->second;
    auto schema_id = schemas_.find(std::string(schema_name));
    if (schema_id == schemas_.end()) {
      schema_id = schemas_.emplace(schema_name, writer_.add_schema(schema_name, "jsonschema", schema)).first;
    }
    return channels_[topic] = writer_.add_channel(schema_id->second, topic, "json", metadata);
  }

 private:
  mcap::Writer& writer_;
  std::map<std::string, std::uint16_t> schemas_, channels_;
};

// An MCAP export under way: the session's clock and links, the writer and its channels, the messages counted.
class McapExport {
 public:
  McapExport(const store::Store& store, std::int64_t session, std::ostream& out)
      : store_(store),
        session_(session),
        clock_(store, session, ""),
        links_(links_by_id(store, session)),
        writer_(out, "imubridge " IMUBRIDGE_VERSION) {}

  void samples() {
    store_.for_each_sample(session_, std::nullopt, [&](const protocol::Sample& s) {
      const std::int64_t t = clock_.device_ns(s.link_id, s.device_time_us);
      nlohmann::ordered_json j{{"session_t_s", seconds(t)},
                               {"link_id", s.link_id},
                               {"seq", s.seq},
                               {"device_time_us", s.device_time_us},
                               {"recv_mono_ns", s.recv_mono_ns},
                               {"ax", s.accel[0]},
                               {"ay", s.accel[1]},
                               {"az", s.accel[2]},
                               {"gx", s.gyro[0]},
                               {"gy", s.gyro[1]},
                               {"gz", s.gyro[2]},
                               {"mx", optional_number(s.has_mag, s.mag[0])},
                               {"my", optional_number(s.has_mag, s.mag[1])},
                               {"mz", optional_number(s.has_mag, s.mag[2])},
                               {"temperature_c", optional_number(s.has_temperature, s.temperature_c)}};
      const auto channel = channels_.get("/" + link_name(s.link_id) + "/imu", "imubridge.ImuSample", sample_schema(),
                                         link_metadata(s.link_id));
      writer_.write(channel, device_log_time(t), json_text(j));
      ++counts_.samples;
    });
    writer_.close_chunk();
  }

  void estimates(std::int64_t run) {
    store_.for_each_estimate(run, [&](const store::Estimate& e) {
      const std::int64_t t = clock_.estimate_ns(e.link_id, e.t_s);
      nlohmann::ordered_json j{{"session_t_s", seconds(t)},
                               {"link_id", e.link_id},
                               {"seq", e.seq},
                               {"device_t_s", e.t_s},
                               {"fx", e.fx},
                               {"fy", e.fy},
                               {"vx", e.vx},
                               {"vy", e.vy},
                               {"var_vx", e.var_vx},
                               {"var_vy", e.var_vy}};
      auto metadata = link_metadata(e.link_id);
      metadata["run_id"] = std::to_string(run);
      const auto channel = channels_.get("/" + link_name(e.link_id) + "/estimate", "imubridge.VelocityEstimate",
                                         estimate_schema(), metadata);
      writer_.write(channel, device_log_time(t), json_text(j));
      ++counts_.estimates;
    });
    writer_.close_chunk();
  }

  void reference() {
    store_.for_each_reference(session_, [&](const store::ReferenceRow& r) {
      const std::uint64_t time = log_time(r.t_ns);
      const double session_t_s = seconds(clock_.mono_ns(r.t_ns));
      const auto& p = r.position;
      const auto& q = r.quat_wxyz;
      nlohmann::ordered_json pose{{"timestamp", time_json(time)},
                                  {"frame_id", "reference"},
                                  {"pose",
                                   {{"position", {{"x", p[0]}, {"y", p[1]}, {"z", p[2]}}},
                                    {"orientation", {{"x", q[1]}, {"y", q[2]}, {"z", q[3]}, {"w", q[0]}}}}},
                                  {"session_t_s", session_t_s}};
      writer_.write(channels_.get("/reference/pose", "foxglove.PoseInFrame", pose_in_frame_schema()), time,
                    json_text(pose));
      if (r.velocity) {
        const auto& v = *r.velocity;
        nlohmann::ordered_json velocity{
            {"session_t_s", session_t_s}, {"mono_ns", r.t_ns}, {"vx", v[0]}, {"vy", v[1]}, {"vz", v[2]}};
        writer_.write(channels_.get("/reference/velocity", "imubridge.ReferenceVelocity", velocity_schema()), time,
                      json_text(velocity));
      }
      ++counts_.reference;
    });
    writer_.close_chunk();
  }

  void events() {
    for (const store::Event& e : store_.events(session_)) {
      const std::uint64_t time = log_time(e.mono_ns);
      std::string message = e.kind;
      if (e.count != 1) message += " (" + std::to_string(e.count) + " times)";
      if (!e.detail.empty()) message += ": " + e.detail;
      // foxglove.Log's fields, then the event's own, so nothing of it is lost.
      nlohmann::ordered_json j{{"timestamp", time_json(time)},
                               {"level", log_level(e.kind)},
                               {"message", message},
                               {"name", e.link_id ? link_name(*e.link_id) : "session"},
                               {"file", ""},
                               {"line", 0},
                               {"session_t_s", seconds(clock_.mono_ns(e.mono_ns))},
                               {"link_id", e.link_id ? nlohmann::ordered_json(*e.link_id) : nullptr},
                               {"mono_ns", e.mono_ns},
                               {"wall_ns", e.wall_ns},
                               {"kind", e.kind},
                               {"count", e.count},
                               {"detail", e.detail}};
      writer_.write(channels_.get("/events", "foxglove.Log", log_schema()), time, json_text(j));
      ++counts_.events;
    }
  }

  McapCounts finish() {
    writer_.finish();
    return counts_;
  }

 private:
  static std::map<std::int64_t, store::Link> links_by_id(const store::Store& store, std::int64_t session) {
    std::map<std::int64_t, store::Link> links;
    for (const auto& link : store.links(session)) links[link.id] = link;
    return links;
  }
  // Samples and estimates are timed by the IMU's clock: on the monotonic line through their link's first sample.
  std::uint64_t device_log_time(std::int64_t session_ns) const {
    return log_time(clock_.origin_mono_ns() + session_ns);
  }
  std::string link_name(std::int64_t id) const {
    const auto it = links_.find(id);
    return it != links_.end() ? it->second.name : "link" + std::to_string(id);
  }
  std::map<std::string, std::string> link_metadata(std::int64_t id) const {
    std::map<std::string, std::string> metadata{{"link_id", std::to_string(id)}};
    if (const auto it = links_.find(id); it != links_.end()) {
      metadata["protocol"] = it->second.protocol;
      metadata["device"] = it->second.device;
    }
    return metadata;
  }

  const store::Store& store_;
  std::int64_t session_;
  const SessionClock clock_;
  const std::map<std::int64_t, store::Link> links_;
  mcap::Writer writer_;
  McapChannels channels_{writer_};
  McapCounts counts_;
};

}  // namespace

McapCounts export_mcap(const store::Store& store, std::int64_t session, std::optional<std::int64_t> run,
                       std::ostream& out) {
  find_session(store, session);
  const std::optional<std::int64_t> chosen = estimates_run(store, session, run, false);
  McapExport mcap(store, session, out);
  mcap.samples();
  if (chosen) mcap.estimates(*chosen);
  mcap.reference();
  mcap.events();
  return mcap.finish();
}

}  // namespace imubridge::replay
