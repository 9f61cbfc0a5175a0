#include "importers/ulog_import.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <utility>
#include <vector>

#include "importers/log_import.hpp"
#include "importers/ulog.hpp"

namespace imubridge::importers {
namespace {

// PX4 marks a relative timestamp whose sensor had no new sample with INT32_MAX.
constexpr double kRelativeTimestampInvalid = std::numeric_limits<std::int32_t>::max();
std::int64_t ns(std::uint64_t us) { return static_cast<std::int64_t>(us) * 1000; }

// The leaves `names` of `topic`, or nothing if any is missing.
template <std::size_t N>
std::optional<std::array<std::size_t, N>> leaves(const ulog::Topic& topic, const std::array<const char*, N>& names) {
  return columns(topic, &ulog::Topic::leaf, names);
}

std::vector<ImuRow> from_sensor_combined(const ulog::Topic& topic, std::map<std::string, std::uint64_t>& skipped) {
  std::vector<ImuRow> rows;
  const auto gyro = leaves<3>(topic, {"gyro_rad[0]", "gyro_rad[1]", "gyro_rad[2]"});
  const auto accel = leaves<3>(topic, {"accelerometer_m_s2[0]", "accelerometer_m_s2[1]", "accelerometer_m_s2[2]"});
  if (!gyro || !accel) return rows;
  const auto relative = topic.leaf("accelerometer_timestamp_relative");
  for (std::size_t i = 0; i < topic.size(); ++i) {
    ImuRow row{.t_us = topic.timestamp(i), .accel = vec3(topic, i, *accel), .gyro = vec3(topic, i, *gyro)};
    if (relative && topic.value(i, *relative) == kRelativeTimestampInvalid) {
      ++skipped["no accelerometer sample (relative timestamp invalid)"];
    } else if (!finite(row.accel) || !finite(row.gyro)) {
      ++skipped["not a finite number"];
    } else {
      append_in_order(row, rows, skipped);
    }
  }
  return rows;
}

// Each gyro sample with the accelerometer interpolated linearly to its time.
std::vector<ImuRow> from_accel_and_gyro(const ulog::Topic& accel_topic, const ulog::Topic& gyro_topic,
                                        std::map<std::string, std::uint64_t>& skipped) {
  const auto a = leaves<3>(accel_topic, {"x", "y", "z"});
  const auto g = leaves<3>(gyro_topic, {"x", "y", "z"});
  if (!a || !g) return {};
  std::vector<TimedVector> accel, gyro;
  for (std::size_t i = 0; i < accel_topic.size(); ++i) {
    const std::uint64_t t = accel_topic.timestamp(i);
    const auto v = vec3(accel_topic, i, *a);
    if (finite(v) && (accel.empty() || t > accel.back().first)) accel.emplace_back(t, v);
  }
  for (std::size_t i = 0; i < gyro_topic.size(); ++i)
    gyro.emplace_back(gyro_topic.timestamp(i), vec3(gyro_topic, i, *g));
  return pair_accel_with_gyro(accel, gyro, skipped);
}

// Rows at vehicle_local_position's times, the attitude interpolated (slerp) from vehicle_attitude's bracketing
// samples: position needs both, and the estimator's reference pairs every position with an attitude.
std::vector<store::ReferenceRow> reference_rows(const ulog::Log& log, std::map<std::string, std::uint64_t>& skipped) {
  std::vector<store::ReferenceRow> rows;
  const ulog::Topic* att_topic = log.topic("vehicle_attitude");
  const ulog::Topic* lp = log.topic("vehicle_local_position");
  if (!att_topic || !lp) return rows;
  const auto q = leaves<4>(*att_topic, {"q[0]", "q[1]", "q[2]", "q[3]"});
  const auto p = leaves<3>(*lp, {"x", "y", "z"});
  if (!q || !p) return rows;
  const auto v = leaves<3>(*lp, {"vx", "vy", "vz"});
  const auto flag = [&](std::size_t record, const char* name) {  // absent flags: older logs, taken as valid
    const auto leaf = lp->leaf(name);
    return !leaf || lp->value(record, *leaf) != 0;
  };
  AttitudeSeries attitude;
  for (std::size_t i = 0; i < att_topic->size(); ++i) {
    attitude.add(att_topic->timestamp(i),
                 Eigen::Quaterniond(att_topic->value(i, (*q)[0]), att_topic->value(i, (*q)[1]),
                                    att_topic->value(i, (*q)[2]), att_topic->value(i, (*q)[3])),
                 skipped);
  }
  for (std::size_t i = 0; i < lp->size(); ++i) {
    const std::uint64_t t = lp->timestamp(i);
    const auto position = vec3(*lp, i, *p);
    // Without a horizontal fix (no GPS, vision or flow) PX4 holds x and y at 0: no truth to compare against.
    if (!flag(i, "xy_valid")) {
      ++skipped["horizontal position not valid (xy_valid false)"];
      continue;
    }
    if (!flag(i, "z_valid") || !finite(position)) {
      ++skipped["height not valid (z_valid false) or not a finite number"];
      continue;
    }
    const std::optional<Eigen::Quaterniond> a = attitude.at(t);
    if (!a) {
      ++skipped["no attitude around it"];
      continue;
    }
    if (!rows.empty() && ns(t) <= rows.back().t_ns) {
      ++skipped["timestamp not after the previous row's"];
      continue;
    }
    auto& row = rows.emplace_back(
        store::ReferenceRow{.t_ns = ns(t), .position = position, .quat_wxyz = {a->w(), a->x(), a->y(), a->z()}});
    if (v && flag(i, "v_xy_valid") && flag(i, "v_z_valid")) {
      const auto velocity = vec3(*lp, i, *v);
      if (finite(velocity)) row.velocity = velocity;
    }
  }
  return rows;
}

std::string seconds_text(std::uint64_t us) {
  char text[32];
  std::snprintf(text, sizeof text, "%.1f s", static_cast<double>(us) * 1e-6);
  return text;
}

// The intervals the land detector said the vehicle was not landed, in its records' order.
std::optional<std::vector<UlogImportResult::Interval>> airborne_intervals(const ulog::Log& log) {
  const ulog::Topic* detector = log.topic("vehicle_land_detected");
  if (detector == nullptr || detector->size() == 0) return std::nullopt;
  const auto landed = detector->leaf("landed");
  if (!landed) return std::nullopt;
  std::vector<UlogImportResult::Interval> flights;
  bool flying = false;
  std::uint64_t takeoff_us = 0;
  for (std::size_t i = 0; i < detector->size(); ++i) {
    const std::uint64_t t = detector->timestamp(i);
    const bool on_ground = detector->value(i, *landed) != 0.0;
    if (!on_ground && !flying) {
      flying = true;
      takeoff_us = t;
    } else if (on_ground && flying) {
      flights.push_back({takeoff_us, t});
      flying = false;
    }
  }
  if (flying) flights.push_back({takeoff_us, detector->timestamp(detector->size() - 1)});
  return flights;
}

std::string level_name(std::uint8_t level) {
  static const char* const kNames[] = {"emergency", "alert", "critical", "error", "warning", "notice", "info", "debug"};
  return level >= '0' && level <= '7' ? kNames[level - '0'] : "level " + std::to_string(level);
}

nlohmann::json metadata(const ulog::Log& log, const UlogImportOptions& options, const std::string& imu_source,
                        bool reference) {
  nlohmann::json topics = nlohmann::json::array();
  for (const auto& t : log.topics) {
    topics.push_back(
        {{"name", t.name}, {"multi_id", t.multi_id}, {"records", t.size()}, {"appended_records", t.appended_records}});
  }
  nlohmann::json changes = nlohmann::json::array();
  for (const auto& c : log.param_changes)
    changes.push_back({{"after_us", c.after_us}, {"name", c.name}, {"value", c.value}});
  return {{"import",
           {{"format", "ulog"},
            {"file", options.file.string()},
            {"imu_source", imu_source},
            {"reference", reference ? "vehicle_attitude + vehicle_local_position" : ""},
            {"accel_lsb", options.accel_lsb},
            {"gyro_lsb", options.gyro_lsb},
            {"ulog_version", log.version},
            {"start_us", log.start_us},
            {"data_appended", log.data_appended},
            {"appended_offsets", log.appended_offsets},
            {"appended_messages", log.appended_messages},
            {"info", log.info},
            {"multi_info", log.multi_info},
            {"params", log.params},
            {"default_params", log.default_params},
            {"param_changes", changes},
            {"topics", topics},
            {"skipped_messages", log.skipped},
            {"damage", log.damage ? nlohmann::json(*log.damage) : nlohmann::json(nullptr)}}}};
}

}  // namespace

UlogImportResult import_ulog(store::Store& store, const UlogImportOptions& options) {
  const ImuLogSettings settings =
      imu_log_settings(options.accel_lsb, options.gyro_lsb, options.imu_axes, options.gap_threshold_s, options.progress,
                       options.file, options.on_problem);
  const ulog::Log log = ulog::read_file(options.file, options.progress);
  const std::string file = options.file.string();

  UlogImportResult result;
  ImuLog imported{.source = "PX4 ULog " + file, .file = file};
  if (const ulog::Topic* combined = log.topic("sensor_combined"); combined && combined->size() > 0) {
    imported.imu_source = "sensor_combined";
    imported.rows = from_sensor_combined(*combined, imported.skipped);
  } else if (const ulog::Topic* accel = log.topic("sensor_accel"), *gyro = log.topic("sensor_gyro"); accel && gyro) {
    imported.imu_source = "sensor_accel+sensor_gyro";
    imported.rows = from_accel_and_gyro(*accel, *gyro, imported.skipped);
  }
  if (imported.rows.empty()) {
    throw std::invalid_argument(file + ": no IMU samples (" +
                                (imported.imu_source.empty()
                                     ? "neither sensor_combined nor sensor_accel and sensor_gyro"
                                     : imported.imu_source + " has no usable record") +
                                (log.damage ? "; the file is damaged: " + *log.damage : "") + ")");
  }
  if (options.reference) imported.reference = reference_rows(log, imported.reference_skipped);
  imported.device = "PX4 " + imported.imu_source + ", " + file;
  imported.config = metadata(log, options, imported.imu_source, !imported.reference.empty());
  imported.damage = log.damage;
  result.data_appended = log.data_appended;
  result.appended_messages = log.appended_messages;

  for (const auto& s : log.strings) {
    imported.events.push_back(
        {s.timestamp_us, "log",
         level_name(s.level) + (s.tag ? " (tag " + std::to_string(*s.tag) + ")" : "") + ": " + s.text});
    ++result.log_events;
  }
  for (const auto& d : log.dropouts) {
    imported.events.push_back(
        {d.after_us, "dropout", "the logger dropped " + std::to_string(d.duration_ms) + " ms of data"});
    ++result.dropouts;
    result.dropout_ms += d.duration_ms;
  }
  result.airborne = airborne_intervals(log);
  if (result.airborne) {
    for (const auto& flight : *result.airborne) {
      imported.events.push_back({flight.from_us, "takeoff", "vehicle_land_detected: no longer landed"});
      imported.events.push_back(
          {flight.to_us, "landing",
           "vehicle_land_detected: landed, after " + seconds_text(flight.to_us - flight.from_us) + " in the air"});
    }
  }
  record_imu_log(store, std::move(imported), settings, result);
  return result;
}

}  // namespace imubridge::importers
