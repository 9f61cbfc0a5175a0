#include "replay/export.hpp"

#include <charconv>
#include <cmath>
#include <initializer_list>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <variant>
#include <vector>

#include "replay/session_lookup.hpp"

namespace imubridge::replay {
namespace {

using Value = std::variant<std::nullptr_t, std::int64_t, std::uint64_t, double, std::string_view>;

class RowWriter {
 public:
  RowWriter(ExportFormat format, std::ostream& out, std::initializer_list<const char*> columns)
      : format_(format), out_(out), columns_(columns) {
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

std::int64_t estimates_run(const store::Store& store, std::int64_t session, std::optional<std::int64_t> run) {
  if (run) return find_run(store, session, *run).id;
  const auto runs = store.runs(session);
  if (runs.size() == 1) return runs.front().id;
  const std::string s = "session " + std::to_string(session);
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
  throw std::invalid_argument("unknown export format \"" + std::string(name) + "\" (csv, jsonl)");
}

void export_table(const store::Store& store, std::int64_t session, ExportTable table, std::optional<std::int64_t> run,
                  ExportFormat format, std::ostream& out) {
  find_session(store, session);
  if (run && table != ExportTable::estimates) throw std::invalid_argument("--run selects estimates only");
  switch (table) {
    case ExportTable::samples: {
      RowWriter w(format, out,
                  {"link_id", "seq", "device_time_us", "recv_mono_ns", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my",
                   "mz", "temperature_c"});
      store.for_each_sample(session, std::nullopt, [&](const protocol::Sample& s) {
        w.row({std::int64_t{s.link_id}, s.seq, s.device_time_us, s.recv_mono_ns, s.accel[0], s.accel[1], s.accel[2],
               s.gyro[0], s.gyro[1], s.gyro[2], optional_real(s.has_mag, s.mag[0]), optional_real(s.has_mag, s.mag[1]),
               optional_real(s.has_mag, s.mag[2]), optional_real(s.has_temperature, s.temperature_c)});
      });
      break;
    }
    case ExportTable::estimates: {
      const std::int64_t chosen = estimates_run(store, session, run);  // before any output: it may fail
      RowWriter w(format, out, {"link_id", "seq", "t_s", "fx", "fy", "vx", "vy", "var_vx", "var_vy"});
      store.for_each_estimate(chosen, [&](const store::Estimate& e) {
        w.row({e.link_id, e.seq, e.t_s, e.fx, e.fy, e.vx, e.vy, e.var_vx, e.var_vy});
      });
      break;
    }
    case ExportTable::reference: {
      RowWriter w(format, out, {"t_ns", "px", "py", "pz", "qw", "qx", "qy", "qz", "vx", "vy", "vz"});
      store.for_each_reference(session, [&](const store::ReferenceRow& r) {
        const auto& p = r.position;
        const auto& q = r.quat_wxyz;
        const bool has_v = r.velocity.has_value();
        const auto v = r.velocity.value_or(std::array<double, 3>{});
        w.row({r.t_ns, p[0], p[1], p[2], q[0], q[1], q[2], q[3], optional_real(has_v, v[0]), optional_real(has_v, v[1]),
               optional_real(has_v, v[2])});
      });
      break;
    }
    case ExportTable::events: {
      RowWriter w(format, out, {"link_id", "mono_ns", "wall_ns", "kind", "count", "detail"});
      for (const auto& e : store.events(session)) {
        w.row({e.link_id ? Value(*e.link_id) : Value(nullptr), e.mono_ns, e.wall_ns, e.kind, e.count, e.detail});
      }
      break;
    }
  }
  if (!out.flush()) throw std::runtime_error("write error while exporting");
}

}  // namespace imubridge::replay
