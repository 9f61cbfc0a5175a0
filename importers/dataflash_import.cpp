#include "importers/dataflash_import.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <utility>
#include <vector>

#include "importers/dataflash.hpp"

namespace imubridge::importers {
namespace {

constexpr double kRadiansPerDegree = M_PI / 180;
constexpr std::int64_t kArmedEvent = 10, kDisarmedEvent = 11;  // ArduPilot's EV ids
// ArduCopter's land detector (set_land_complete): landed, and no longer landed.
constexpr std::int64_t kLandCompleteEvent = 18, kNotLandedEvent = 28;

std::int64_t ns(std::uint64_t us) { return static_cast<std::int64_t>(us) * 1000; }

// The fields `names` of `m`, or nothing if any is missing.
template <std::size_t N>
std::optional<std::array<std::size_t, N>> fields(const dataflash::Message& m, const std::array<const char*, N>& names) {
  return columns(m, &dataflash::Message::field, names);
}

// The instance a message named `base` + suffix logs: no suffix 0, a number n the (n-1)th ("IMU2": 1, "ACC1": 0);
// nothing when `name` is not `base` so followed.
std::optional<unsigned> instance_of_name(const std::string& name, std::string_view base) {
  if (!name.starts_with(base)) return std::nullopt;
  const std::string suffix = name.substr(base.size());
  if (suffix.empty()) return 0u;
  if (suffix.size() != 1 || !std::isdigit(static_cast<unsigned char>(suffix[0])) || suffix[0] == '0') {
    return std::nullopt;
  }
  return static_cast<unsigned>(suffix[0] - '1');
}

// One IMU instance's series, as the log has them.
struct Instance {
  std::string imu_name, acc_name, gyr_name;  // "IMU2", "IMU[1]" (the I field's instance), "ACC1", ...
  std::vector<ImuRow> imu;                   // from IMU records
  std::vector<TimedVector> acc, gyr;         // from ACC and GYR records
  std::map<std::string, std::uint64_t> skipped;
};

// Calls visit(instance, record) for each record of every message named `base`(+suffix), the instance from the
// record's I field when it has one, else from the name.
template <typename Visit>
void for_each_instance_record(const dataflash::Log& log, std::string_view base, Visit visit) {
  for (const auto& [type, m] : log.messages) {
    const auto named = instance_of_name(m.name, base);
    if (!named) continue;
    const auto i_field = m.field("I");
    for (std::size_t r = 0; r < m.size(); ++r) {
      const auto instance = i_field ? static_cast<unsigned>(m.integer(r, *i_field)) : *named;
      visit(m, i_field ? m.name + "[" + std::to_string(instance) + "]" : m.name, instance, r);
    }
  }
}

std::map<unsigned, Instance> instances(const dataflash::Log& log) {
  std::map<unsigned, Instance> out;
  for_each_instance_record(
      log, "IMU", [&](const dataflash::Message& m, const std::string& label, unsigned instance, std::size_t r) {
        const auto g = fields<3>(m, {"GyrX", "GyrY", "GyrZ"});
        const auto a = fields<3>(m, {"AccX", "AccY", "AccZ"});
        if (!g || !a) return;
        Instance& in = out[instance];
        in.imu_name = label;
        const ImuRow row{.t_us = m.times[r], .accel = vec3(m, r, *a), .gyro = vec3(m, r, *g)};
        if (!finite(row.accel) || !finite(row.gyro)) {
          ++in.skipped["not a finite number"];
        } else {
          append_in_order(row, in.imu, in.skipped);
        }
      });
  // ACC and GYR: a sample's own time (SampleUS) where the record has it, else the record's.
  const auto series = [&](std::string_view base, const std::array<const char*, 3>& names, std::string Instance::*name,
                          std::vector<TimedVector> Instance::*into) {
    for_each_instance_record(
        log, base, [&](const dataflash::Message& m, const std::string& label, unsigned instance, std::size_t r) {
          const auto v = fields<3>(m, names);
          if (!v) return;
          Instance& in = out[instance];
          in.*name = label;
          const auto sample_us = m.field("SampleUS");
          const std::uint64_t t = sample_us ? static_cast<std::uint64_t>(m.integer(r, *sample_us)) : m.times[r];
          const auto value = vec3(m, r, *v);
          auto& s = in.*into;
          if (finite(value) && (s.empty() || t > s.back().first)) s.emplace_back(t, value);
        });
  };
  series("ACC", {"AccX", "AccY", "AccZ"}, &Instance::acc_name, &Instance::acc);
  series("GYR", {"GyrX", "GyrY", "GyrZ"}, &Instance::gyr_name, &Instance::gyr);
  return out;
}

std::string describe(const Instance& in) {
  std::string text;
  if (!in.imu.empty()) text = in.imu_name + ": " + std::to_string(in.imu.size());
  if (!in.acc.empty() && !in.gyr.empty()) {
    text += (text.empty() ? "" : ", ") + in.acc_name + "+" + in.gyr_name + ": " +
            std::to_string(std::min(in.acc.size(), in.gyr.size()));
  }
  return text.empty() ? "no usable record" : text;
}

std::string instance_list(const std::map<unsigned, Instance>& all) {
  std::string text;
  for (const auto& [i, in] : all) text += (text.empty() ? "" : "; ") + std::to_string(i) + ": " + describe(in);
  return text;
}

// The EKF's rows: position and velocity (NED) with its attitude (roll, pitch, yaw), or ATT's where the EKF message
// has none. The newest EKF the log has (XKF1: EKF3, NKF1: EKF2, EKF1: the first EKF), its lowest core where it logs
// several.
std::vector<store::ReferenceRow> reference_rows(const dataflash::Log& log, std::string& source,
                                                std::map<std::string, std::uint64_t>& skipped) {
  std::vector<store::ReferenceRow> rows;
  const dataflash::Message* ekf = nullptr;
  for (const char* name : {"XKF1", "NKF1", "EKF1"}) {
    if (const auto* m = log.message(name); m && m->size() > 0) {
      ekf = m;
      break;
    }
  }
  if (!ekf) return rows;
  const auto p = fields<3>(*ekf, {"PN", "PE", "PD"});
  const auto v = fields<3>(*ekf, {"VN", "VE", "VD"});
  if (!p) return rows;
  const auto angles = fields<3>(*ekf, {"Roll", "Pitch", "Yaw"});
  AttitudeSeries att_series;
  if (!angles) {
    const dataflash::Message* att = log.message("ATT");
    const auto att_angles = att ? fields<3>(*att, {"Roll", "Pitch", "Yaw"}) : std::nullopt;
    if (!att_angles) return rows;
    for (std::size_t r = 0; r < att->size(); ++r) {
      const auto rpy = vec3(*att, r, *att_angles);
      att_series.add(
          att->times[r],
          attitude_from_euler(rpy[0] * kRadiansPerDegree, rpy[1] * kRadiansPerDegree, rpy[2] * kRadiansPerDegree),
          skipped);
    }
  }
  source = ekf->name + (angles ? " (attitude from its Roll, Pitch, Yaw)" : " (attitude from ATT)");
  const auto core = ekf->field("C");
  std::int64_t first_core = std::numeric_limits<std::int64_t>::max();
  for (std::size_t r = 0; core && r < ekf->size(); ++r) first_core = std::min(first_core, ekf->integer(r, *core));
  for (std::size_t r = 0; r < ekf->size(); ++r) {
    if (core && ekf->integer(r, *core) != first_core) continue;
    const std::uint64_t t = ekf->times[r];
    const auto position = vec3(*ekf, r, *p);
    if (!finite(position)) {
      ++skipped["position not a finite number"];
      continue;
    }
    std::optional<Eigen::Quaterniond> q;
    if (angles) {
      const auto rpy = vec3(*ekf, r, *angles);
      if (finite(rpy)) {
        q = attitude_from_euler(rpy[0] * kRadiansPerDegree, rpy[1] * kRadiansPerDegree, rpy[2] * kRadiansPerDegree);
      }
    } else {
      q = att_series.at(t);
    }
    if (!q) {
      ++skipped[angles ? "attitude not a finite number" : "no attitude around it"];
      continue;
    }
    if (!rows.empty() && ns(t) <= rows.back().t_ns) {
      ++skipped["timestamp not after the previous row's"];
      continue;
    }
    auto& row = rows.emplace_back(
        store::ReferenceRow{.t_ns = ns(t), .position = position, .quat_wxyz = {q->w(), q->x(), q->y(), q->z()}});
    if (v) {
      const auto velocity = vec3(*ekf, r, *v);
      if (finite(velocity)) row.velocity = velocity;
    }
  }
  return rows;
}

// ArduCopter's flight modes (its MODE records' numbers); other vehicles' modes are given by number.
std::string copter_mode_name(std::int64_t mode) {
  static const std::map<std::int64_t, const char*> kNames = {
      {0, "STABILIZE"}, {1, "ACRO"},        {2, "ALT_HOLD"},      {3, "AUTO"},        {4, "GUIDED"},
      {5, "LOITER"},    {6, "RTL"},         {7, "CIRCLE"},        {9, "LAND"},        {11, "DRIFT"},
      {13, "SPORT"},    {14, "FLIP"},       {15, "AUTOTUNE"},     {16, "POSHOLD"},    {17, "BRAKE"},
      {18, "THROW"},    {19, "AVOID_ADSB"}, {20, "GUIDED_NOGPS"}, {21, "SMART_RTL"},  {22, "FLOWHOLD"},
      {23, "FOLLOW"},   {24, "ZIGZAG"},     {25, "SYSTEMID"},     {26, "AUTOROTATE"}, {27, "AUTO_RTL"}};
  const auto it = kNames.find(mode);
  return it == kNames.end() ? "" : it->second;
}

// MSG, MODE, arming (EV 10 and 11, or ARM) and the land detector (EV 28 and 18: takeoff and landing) as events, in time
// order (stable: a log's order where times tie).
std::vector<LogEvent> events(const dataflash::Log& log, DataflashImportResult& result) {
  std::vector<LogEvent> out;
  bool copter = false;
  if (const auto* msg = log.message("MSG"); msg) {
    if (const auto text = msg->field("Message")) {
      for (std::size_t r = 0; r < msg->size(); ++r) {
        const std::string line = msg->text(r, *text);
        copter = copter || line.find("Copter") != std::string::npos;
        out.push_back({msg->times[r], "log", line});
        ++result.log_events;
      }
    }
  }
  if (const auto* mode = log.message("MODE"); mode) {
    const auto number = mode->field("ModeNum") ? mode->field("ModeNum") : mode->field("Mode");
    for (std::size_t r = 0; number && r < mode->size(); ++r) {
      const std::int64_t n = mode->integer(r, *number);
      const std::string name = copter ? copter_mode_name(n) : "";
      out.push_back({mode->times[r], "mode", "mode " + std::to_string(n) + (name.empty() ? "" : " (" + name + ")")});
      ++result.mode_changes;
    }
  }
  const auto arming = [&](std::uint64_t t, bool armed, const std::string& from) {
    out.push_back({t, "arming", std::string(armed ? "armed" : "disarmed") + " (" + from + ")"});
    ++result.arming_changes;
  };
  if (const auto* ev = log.message("EV"); ev) {
    for (std::size_t r = 0; ev->field("Id") && r < ev->size(); ++r) {
      const std::int64_t id = ev->integer(r, *ev->field("Id"));
      if (id == kArmedEvent || id == kDisarmedEvent)
        arming(ev->times[r], id == kArmedEvent, "EV " + std::to_string(id));
      // As import ulog stores PX4's: what --in-flight takes the flight from, and where the filter fuses rest.
      if (id == kNotLandedEvent || id == kLandCompleteEvent) {
        const bool landed = id == kLandCompleteEvent;
        out.push_back({ev->times[r], landed ? "landing" : "takeoff",
                       landed ? "the land detector: landed (EV 18, LAND_COMPLETE)"
                              : "the land detector: no longer landed (EV 28, NOT_LANDED)"});
        ++result.land_detector_changes;
      }
    }
  }
  if (const auto* arm = log.message("ARM"); arm) {
    for (std::size_t r = 0; arm->field("ArmState") && r < arm->size(); ++r) {
      arming(arm->times[r], arm->integer(r, *arm->field("ArmState")) != 0, "ARM");
    }
  }
  std::stable_sort(out.begin(), out.end(), [](const LogEvent& a, const LogEvent& b) { return a.t_us < b.t_us; });
  return out;
}

// PARM: each parameter's first value, and its later changes with their times.
std::pair<nlohmann::json, nlohmann::json> parameters(const dataflash::Log& log) {
  nlohmann::json params = nlohmann::json::object(), changes = nlohmann::json::array();
  const auto* parm = log.message("PARM");
  if (!parm) return {params, changes};
  const auto name = parm->field("Name"), value = parm->field("Value");
  for (std::size_t r = 0; name && value && r < parm->size(); ++r) {
    const std::string n = parm->text(r, *name);
    const double v = parm->value(r, *value);
    const nlohmann::json j = std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
    if (!params.contains(n)) {
      params[n] = j;
    } else if (params[n] != j) {
      changes.push_back({{"t_us", parm->times[r]}, {"name", n}, {"value", j}});
    }
  }
  return {params, changes};
}

nlohmann::json metadata(const dataflash::Log& log, const DataflashImportOptions& options,
                        const DataflashImportResult& result, const std::string& imu_source, nlohmann::json params,
                        nlohmann::json changes) {
  nlohmann::json messages = nlohmann::json::object();
  for (const auto& [type, m] : log.messages) messages[m.name] = m.size();
  nlohmann::json imus = nlohmann::json::object();
  for (const auto& [i, text] : result.imus) imus[std::to_string(i)] = text;
  return {{"import",
           {{"format", "dataflash"},
            {"file", options.file.string()},
            {"imu_instance", result.instance},
            {"imu_source", imu_source},
            {"imus", imus},
            {"reference", result.reference_source},
            {"accel_lsb", options.accel_lsb},
            {"gyro_lsb", options.gyro_lsb},
            {"records", log.records},
            {"messages", messages},
            {"params", std::move(params)},
            {"param_changes", std::move(changes)},
            {"damage", log.damage ? nlohmann::json(*log.damage) : nlohmann::json(nullptr)}}}};
}

}  // namespace

DataflashImportResult import_dataflash(store::Store& store, const DataflashImportOptions& options) {
  const ImuLogSettings settings =
      imu_log_settings(options.accel_lsb, options.gyro_lsb, options.imu_axes, options.gap_threshold_s, options.progress,
                       options.file, options.on_problem);
  const dataflash::Log log = dataflash::read_file(options.file, options.progress);
  const std::string file = options.file.string();

  DataflashImportResult result;
  std::map<unsigned, Instance> all = instances(log);
  for (const auto& [i, in] : all) result.imus[i] = describe(in);
  const auto damage_note = [&] { return log.damage ? "; the file is damaged: " + *log.damage : std::string(); };
  if (all.empty()) {
    throw std::invalid_argument(file + ": no IMU samples (no IMU, or ACC and GYR, records" + damage_note() + ")");
  }
  result.instance = options.imu.value_or(all.contains(0) ? 0 : all.begin()->first);
  const auto chosen = all.find(result.instance);
  if (chosen == all.end()) {
    throw std::invalid_argument(file + ": no IMU instance " + std::to_string(result.instance) +
                                " (its IMUs: " + instance_list(all) + ")");
  }
  Instance& in = chosen->second;
  ImuLog imported{.source = "ArduPilot DataFlash " + file, .file = file};
  imported.skipped = std::move(in.skipped);
  // ACC with GYR where they are logged faster than IMU (INS_RAW_LOG_OPT, the older INS_LOG_BAT): the sensors' rate.
  const std::size_t paired = std::min(in.acc.size(), in.gyr.size());
  if (paired > in.imu.size()) {
    imported.imu_source = in.acc_name + "+" + in.gyr_name;
    imported.rows = pair_accel_with_gyro(in.acc, in.gyr, imported.skipped);
  } else {
    imported.imu_source = in.imu_name;
    imported.rows = std::move(in.imu);
  }
  if (imported.rows.empty()) {
    throw std::invalid_argument(file + ": no IMU samples (" + imported.imu_source + " has no usable record" +
                                damage_note() + ")");
  }
  if (options.reference) {
    imported.reference = reference_rows(log, result.reference_source, imported.reference_skipped);
  }
  if (imported.reference.empty()) result.reference_source.clear();
  imported.device = "ArduPilot " + imported.imu_source + ", " + file;
  imported.events = events(log, result);
  auto [params, changes] = parameters(log);
  result.params = params.size();
  imported.config = metadata(log, options, result, imported.imu_source, std::move(params), std::move(changes));
  imported.damage = log.damage;
  record_imu_log(store, std::move(imported), settings, result);
  return result;
}

}  // namespace imubridge::importers
