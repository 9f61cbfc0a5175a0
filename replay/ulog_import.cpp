#include "replay/ulog_import.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <utility>
#include <vector>

#include "pipeline/record_and_decode.hpp"
#include "pipeline/recorded_session.hpp"
#include "pipeline/session_engine.hpp"
#include "protocol/imu_frame.hpp"
#include "replay/euroc_import.hpp"
#include "replay/ulog.hpp"

namespace imubridge::replay {
namespace {

// PX4 marks a relative timestamp whose sensor had no new sample with INT32_MAX.
constexpr double kRelativeTimestampInvalid = std::numeric_limits<std::int32_t>::max();
// Accelerometer samples further apart than this are not interpolated across (sensor_accel + sensor_gyro).
constexpr std::uint64_t kMaxAccelGapUs = 100'000;
// Attitudes further apart than this are not interpolated across for a reference row.
constexpr std::uint64_t kMaxAttitudeGapUs = 500'000;

struct ImuRow {
  std::uint64_t t_us = 0;
  std::array<double, 3> accel{}, gyro{};
};

std::int64_t ns(std::uint64_t us) { return static_cast<std::int64_t>(us) * 1000; }

bool finite(const std::array<double, 3>& v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

// The leaves `names` of `topic`, or nothing if any is missing.
template <std::size_t N>
std::optional<std::array<std::size_t, N>> leaves(const ulog::Topic& topic, const std::array<const char*, N>& names) {
  std::array<std::size_t, N> out{};
  for (std::size_t i = 0; i < N; ++i) {
    const auto leaf = topic.leaf(names[i]);
    if (!leaf) return std::nullopt;
    out[i] = *leaf;
  }
  return out;
}

std::array<double, 3> vec3(const ulog::Topic& topic, std::size_t record, const std::array<std::size_t, 3>& at) {
  return {topic.value(record, at[0]), topic.value(record, at[1]), topic.value(record, at[2])};
}

// Keeps rows in increasing time: PX4 topics are, but a damaged or odd log may not be.
bool in_order(std::uint64_t t, const std::vector<ImuRow>& rows, std::map<std::string, std::uint64_t>& skipped) {
  if (!rows.empty() && t <= rows.back().t_us) {
    ++skipped["timestamp not after the previous sample's"];
    return false;
  }
  return true;
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
    } else if (in_order(row.t_us, rows, skipped)) {
      rows.push_back(row);
    }
  }
  return rows;
}

// Each gyro sample with the accelerometer interpolated linearly to its time.
std::vector<ImuRow> from_accel_and_gyro(const ulog::Topic& accel_topic, const ulog::Topic& gyro_topic,
                                        std::map<std::string, std::uint64_t>& skipped) {
  std::vector<ImuRow> rows;
  const auto a = leaves<3>(accel_topic, {"x", "y", "z"});
  const auto g = leaves<3>(gyro_topic, {"x", "y", "z"});
  if (!a || !g) return rows;
  std::vector<std::pair<std::uint64_t, std::array<double, 3>>> accel;
  for (std::size_t i = 0; i < accel_topic.size(); ++i) {
    const std::uint64_t t = accel_topic.timestamp(i);
    const auto v = vec3(accel_topic, i, *a);
    if (finite(v) && (accel.empty() || t > accel.back().first)) accel.emplace_back(t, v);
  }
  std::size_t k = 0;
  for (std::size_t i = 0; i < gyro_topic.size(); ++i) {
    ImuRow row{.t_us = gyro_topic.timestamp(i), .gyro = vec3(gyro_topic, i, *g)};
    while (k + 1 < accel.size() && accel[k + 1].first < row.t_us) ++k;
    if (accel.size() < 2 || row.t_us < accel[k].first || k + 1 >= accel.size() || accel[k + 1].first < row.t_us ||
        accel[k + 1].first - accel[k].first > kMaxAccelGapUs) {
      ++skipped["no accelerometer samples around it"];
      continue;
    }
    const double f =
        static_cast<double>(row.t_us - accel[k].first) / static_cast<double>(accel[k + 1].first - accel[k].first);
    for (int j = 0; j < 3; ++j) row.accel[j] = accel[k].second[j] + f * (accel[k + 1].second[j] - accel[k].second[j]);
    if (!finite(row.gyro)) {
      ++skipped["not a finite number"];
    } else if (in_order(row.t_us, rows, skipped)) {
      rows.push_back(row);
    }
  }
  return rows;
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
  std::vector<std::pair<std::uint64_t, Eigen::Quaterniond>> attitude;
  for (std::size_t i = 0; i < att_topic->size(); ++i) {
    const Eigen::Quaterniond a(att_topic->value(i, (*q)[0]), att_topic->value(i, (*q)[1]), att_topic->value(i, (*q)[2]),
                               att_topic->value(i, (*q)[3]));
    const std::uint64_t t = att_topic->timestamp(i);
    if (!(std::abs(a.norm() - 1) <= 1e-2)) {  // also NaN: a filter not yet initialised
      ++skipped["attitude quaternion not of unit length"];
    } else if (attitude.empty() || t > attitude.back().first) {
      attitude.emplace_back(t, a.normalized());
    }
  }
  std::size_t k = 0;
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
    while (k + 1 < attitude.size() && attitude[k + 1].first < t) ++k;
    if (attitude.empty() || t < attitude[k].first ||
        (k + 1 < attitude.size() ? attitude[k + 1].first < t : attitude[k].first != t)) {
      ++skipped["no attitude around it"];
      continue;
    }
    Eigen::Quaterniond a = attitude[k].second;
    if (attitude[k].first != t) {
      const auto& [t1, q1] = attitude[k + 1];
      if (t1 - attitude[k].first > kMaxAttitudeGapUs) {
        ++skipped["no attitude around it"];
        continue;
      }
      a = a.slerp(static_cast<double>(t - attitude[k].first) / static_cast<double>(t1 - attitude[k].first), q1);
    }
    if (!rows.empty() && ns(t) <= rows.back().t_ns) {
      ++skipped["timestamp not after the previous row's"];
      continue;
    }
    auto& row = rows.emplace_back(
        store::ReferenceRow{.t_ns = ns(t), .position = position, .quat_wxyz = {a.w(), a.x(), a.y(), a.z()}});
    if (v && flag(i, "v_xy_valid") && flag(i, "v_z_valid")) {
      const auto velocity = vec3(*lp, i, *v);
      if (finite(velocity)) row.velocity = velocity;
    }
  }
  return rows;
}

bool beyond_range(const std::array<double, 3>& si, double lsb) {
  for (double x : si) {
    if (std::abs(std::round(x / lsb)) > std::numeric_limits<std::int16_t>::max()) return true;
  }
  return false;
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
  const auto calibration = import_calibration(options.accel_lsb, options.gyro_lsb);
  if (!calibration.valid() || !(options.accel_lsb > 0) || !(options.gyro_lsb > 0)) {
    throw std::invalid_argument("the accelerometer and gyro resolutions must be positive and finite");
  }
  const estimator::ImuAxes declared_axes = estimator::parse_imu_axes(options.imu_axes);
  const ulog::Log log = ulog::read_file(options.file, options.progress);
  const std::uint64_t file_size = options.progress ? std::filesystem::file_size(options.file) : 0;
  const std::string file = options.file.string();

  UlogImportResult result;
  std::vector<ImuRow> rows;
  if (const ulog::Topic* combined = log.topic("sensor_combined"); combined && combined->size() > 0) {
    result.imu_source = "sensor_combined";
    rows = from_sensor_combined(*combined, result.skipped);
  } else if (const ulog::Topic* accel = log.topic("sensor_accel"), *gyro = log.topic("sensor_gyro"); accel && gyro) {
    result.imu_source = "sensor_accel+sensor_gyro";
    rows = from_accel_and_gyro(*accel, *gyro, result.skipped);
  }
  if (rows.empty()) {
    throw std::invalid_argument(file + ": no IMU samples (" +
                                (result.imu_source.empty() ? "neither sensor_combined nor sensor_accel and sensor_gyro"
                                                           : result.imu_source + " has no usable record") +
                                (log.damage ? "; the file is damaged: " + *log.damage : "") + ")");
  }
  std::vector<store::ReferenceRow> reference;
  if (options.reference) reference = reference_rows(log, result.reference_skipped);
  result.reference_rows = reference.size();
  result.data_appended = log.data_appended;
  result.appended_messages = log.appended_messages;
  result.damage = log.damage;

  // Both receive clocks are the ULog timestamp (µs since the flight controller booted) in ns, so samples, reference
  // and events share one time line; the device clock is the same timestamp in µs. The frames go through the session
  // engine without estimation: an import has no parameters (a replay estimates).
  const std::int64_t t0 = ns(rows.front().t_us);
  pipeline::RecordedSession recorded = pipeline::begin_recorded_session(
      store,
      {.kind = "import",
       .source = "PX4 ULog " + file,
       .config = metadata(log, options, result.imu_source, !reference.empty()),
       .started_wall_ns = t0},
      {{.recorded = {"imu0", protocol::WireFormat::imubridge, calibration, options.imu_axes},
        .device = "PX4 " + result.imu_source + ", " + file}});
  result.session = recorded.id;
  const std::int64_t link = recorded.store_links[0];
  pipeline::RecordAndDecode recording(std::move(recorded.recorders[0]));
  pipeline::SessionEngine engine(nullptr);

  std::vector<std::uint8_t> bytes;
  std::vector<double> axes_t;
  std::vector<Eigen::Vector3d> axes_accel, axes_gyro;
  for (const ImuRow& row : rows) {
    if (beyond_range(row.accel, options.accel_lsb) || beyond_range(row.gyro, options.gyro_lsb)) ++result.clipped;
    bytes.clear();
    protocol::imu::encode({.seq = static_cast<std::uint16_t>(result.samples),
                           .device_time_us = row.t_us,
                           .payload = calibration.to_counts(row.accel, row.gyro, {}, 0.0)},
                          bytes);
    engine.on_chunk(0, recording, bytes, ns(row.t_us), ns(row.t_us));
    ++result.samples;
    axes_t.push_back(static_cast<double>(row.t_us - rows.front().t_us) * 1e-6);
    axes_accel.emplace_back(row.accel[0], row.accel[1], row.accel[2]);
    axes_gyro.emplace_back(row.gyro[0], row.gyro[1], row.gyro[2]);
    store.commit_if_due(std::chrono::steady_clock::now());
    if (options.progress && result.samples % kImportProgressEvery == 0) {
      options.progress({.bytes_read = file_size, .bytes_total = file_size, .samples = result.samples});
    }
  }
  if (options.progress)
    options.progress({.bytes_read = file_size, .bytes_total = file_size, .samples = result.samples});
  result.first_us = rows.front().t_us;
  result.last_us = rows.back().t_us;
  std::int64_t end = ns(result.last_us);
  engine.finish_link(0, recording, end, end);
  engine.finish();
  for (const auto& row : reference) store.append_reference(result.session, row);

  const auto event = [&](std::optional<std::int64_t> on, std::int64_t t, std::string kind, std::int64_t count,
                         std::string detail) {
    store.append_event(result.session, {.link_id = on,
                                        .mono_ns = t,
                                        .wall_ns = t,
                                        .kind = std::move(kind),
                                        .count = count,
                                        .detail = std::move(detail)});
    end = std::max(end, t);
  };
  for (const auto& s : log.strings) {
    event(std::nullopt, ns(s.timestamp_us), "log", 1,
          level_name(s.level) + (s.tag ? " (tag " + std::to_string(*s.tag) + ")" : "") + ": " + s.text);
    ++result.log_events;
  }
  for (const auto& d : log.dropouts) {
    event(std::nullopt, ns(d.after_us), "dropout", 1,
          "the logger dropped " + std::to_string(d.duration_ms) + " ms of data");
    ++result.dropouts;
    result.dropout_ms += d.duration_ms;
  }
  result.airborne = airborne_intervals(log);
  if (result.airborne) {
    for (const auto& flight : *result.airborne) {
      event(std::nullopt, ns(flight.from_us), "takeoff", 1, "vehicle_land_detected: no longer landed");
      event(std::nullopt, ns(flight.to_us), "landing", 1,
            "vehicle_land_detected: landed, after " + seconds_text(flight.to_us - flight.from_us) + " in the air");
    }
  }
  const std::int64_t last = ns(result.last_us);
  for (const auto& [reason, count] : result.skipped) {
    event(link, last, "import_skipped", static_cast<std::int64_t>(count),
          file + ": " + std::to_string(count) + " " + result.imu_source + " records: " + reason);
  }
  for (const auto& [reason, count] : result.reference_skipped) {
    event(std::nullopt, last, "import_skipped", static_cast<std::int64_t>(count),
          file + ": " + std::to_string(count) + " reference rows: " + reason);
  }
  if (result.clipped > 0) {
    event(link, last, "import_clipped", static_cast<std::int64_t>(result.clipped),
          file + ": " + std::to_string(result.clipped) + " samples beyond the frames' range, clipped");
  }
  if (log.damage) {
    event(std::nullopt, last, "import_damaged", 1,
          file + ": read up to the damage, " + *log.damage + "; everything before it is imported");
  }
  result.axes = estimator::resolve_axes(declared_axes, estimator::detect_up(axes_t, axes_accel, axes_gyro));
  if (result.axes.mismatch) event(link, last, "imu_axes_mismatch", 1, *result.axes.mismatch);
  pipeline::end_recorded_session(store, result.session, end);
  return result;
}

}  // namespace imubridge::replay
