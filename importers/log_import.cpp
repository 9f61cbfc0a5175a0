#include "importers/log_import.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>

#include "importers/euroc_import.hpp"
#include "importers/import_session.hpp"
#include "protocol/imu_frame.hpp"

namespace imubridge::importers {
namespace {

std::int64_t ns(std::uint64_t us) { return static_cast<std::int64_t>(us) * 1000; }

}  // namespace

double Gaps::seconds() const {
  double total = 0;
  for (const Gap& g : holes) total += g.seconds();
  return total;
}

void check_gap_threshold(double threshold_s) {
  if (!(threshold_s > 0) || !std::isfinite(threshold_s)) {
    throw std::invalid_argument("--gap-threshold must be a positive number of seconds");
  }
}

Gaps find_gaps(std::span<const std::int64_t> t_ns, double threshold_s, std::int64_t session_start_ns) {
  check_gap_threshold(threshold_s);
  Gaps gaps{.threshold_s = threshold_s, .session_start_ns = session_start_ns};
  for (std::size_t i = 1; i < t_ns.size(); ++i) {
    // In doubles: a log's times can be anything, and their difference must not overflow (the fuzzer's 2^63-1 and -5).
    if ((static_cast<double>(t_ns[i]) - static_cast<double>(t_ns[i - 1])) * 1e-9 > threshold_s)
      gaps.holes.push_back({t_ns[i - 1], t_ns[i]});
  }
  return gaps;
}

void append_gap_events(store::Store& store, std::int64_t session, std::int64_t link, const Gaps& gaps) {
  for (const Gap& g : gaps.holes) {
    char text[160];
    std::snprintf(text, sizeof text, "no IMU sample for %.3f s, from %.3f s to %.3f s of the session (over %g s)",
                  g.seconds(), (static_cast<double>(g.from_ns) - static_cast<double>(gaps.session_start_ns)) * 1e-9,
                  (static_cast<double>(g.to_ns) - static_cast<double>(gaps.session_start_ns)) * 1e-9, gaps.threshold_s);
    store.append_event(session,
                       {.link_id = link, .mono_ns = g.from_ns, .wall_ns = g.from_ns, .kind = "gap", .detail = text});
  }
}

void ImportedSamples::add(double t_s, std::int64_t at_ns, const std::array<double, 3>& a,
                          const std::array<double, 3>& g) {
  t.push_back(t_s);
  t_ns.push_back(at_ns);
  accel.emplace_back(a[0], a[1], a[2]);
  gyro.emplace_back(g[0], g[1], g[2]);
}

Gaps ImportedSamples::record_gaps(store::Store& store, std::int64_t session, std::int64_t link, double threshold_s,
                                  std::int64_t session_start_ns) const {
  Gaps gaps = find_gaps(t_ns, threshold_s, session_start_ns);
  append_gap_events(store, session, link, gaps);
  return gaps;
}

estimator::AxesResolution ImportedSamples::resolve_axes(const estimator::ImuAxes& declared) const {
  return estimator::resolve_axes(declared, estimator::detect_up(t, accel, gyro));
}

bool finite(const std::array<double, 3>& v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

bool beyond_frame_range(const std::array<double, 3>& si, double lsb) {
  for (double x : si) {
    const double counts = std::round(x / lsb);
    if (counts < std::numeric_limits<std::int16_t>::min() || counts > std::numeric_limits<std::int16_t>::max()) {
      return true;
    }
  }
  return false;
}

void append_in_order(const ImuRow& row, std::vector<ImuRow>& rows, std::map<std::string, std::uint64_t>& skipped) {
  if (!rows.empty() && row.t_us <= rows.back().t_us) {
    ++skipped["timestamp not after the previous sample's"];
  } else {
    rows.push_back(row);
  }
}

std::vector<ImuRow> pair_accel_with_gyro(const std::vector<TimedVector>& accel, const std::vector<TimedVector>& gyro,
                                         std::map<std::string, std::uint64_t>& skipped) {
  std::vector<ImuRow> rows;
  std::size_t k = 0;
  for (const auto& [t, g] : gyro) {
    ImuRow row{.t_us = t, .gyro = g};
    while (k + 1 < accel.size() && accel[k + 1].first < t) ++k;
    if (accel.size() < 2 || t < accel[k].first || k + 1 >= accel.size() || accel[k + 1].first < t ||
        accel[k + 1].first - accel[k].first > kMaxAccelGapUs) {
      ++skipped["no accelerometer samples around it"];
      continue;
    }
    const double f = static_cast<double>(t - accel[k].first) / static_cast<double>(accel[k + 1].first - accel[k].first);
    for (int j = 0; j < 3; ++j) row.accel[j] = accel[k].second[j] + f * (accel[k + 1].second[j] - accel[k].second[j]);
    if (!finite(row.gyro)) {
      ++skipped["not a finite number"];
    } else {
      append_in_order(row, rows, skipped);
    }
  }
  return rows;
}

void AttitudeSeries::add(std::uint64_t t_us, const Eigen::Quaterniond& q,
                         std::map<std::string, std::uint64_t>& skipped) {
  if (!(std::abs(q.norm() - 1) <= 1e-2)) {
    ++skipped["attitude quaternion not of unit length"];
  } else if (samples_.empty() || t_us > samples_.back().first) {
    samples_.emplace_back(t_us, q.normalized());
  }
}

std::optional<Eigen::Quaterniond> AttitudeSeries::at(std::uint64_t t) {
  if (samples_.empty()) return std::nullopt;
  if (k_ >= samples_.size() || samples_[k_].first > t) k_ = 0;
  while (k_ + 1 < samples_.size() && samples_[k_ + 1].first <= t) ++k_;
  const auto& [t0, q0] = samples_[k_];
  if (t0 == t) return q0;
  if (t < t0 || k_ + 1 >= samples_.size()) return std::nullopt;
  const auto& [t1, q1] = samples_[k_ + 1];
  if (t1 - t0 > kMaxAttitudeGapUs) return std::nullopt;
  return q0.slerp(static_cast<double>(t - t0) / static_cast<double>(t1 - t0), q1);
}

Eigen::Quaterniond attitude_from_euler(double roll, double pitch, double yaw) {
  return Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
         Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX());
}

ImuLogSettings imu_log_settings(double accel_lsb, double gyro_lsb, const std::string& imu_axes, double gap_threshold_s,
                                const ImportProgressCallback& progress, const std::filesystem::path& file,
                                const ProblemCallback& on_problem) {
  if (!import_calibration(accel_lsb, gyro_lsb).valid() || !(accel_lsb > 0) || !(gyro_lsb > 0)) {
    throw std::invalid_argument("the accelerometer and gyro resolutions must be positive and finite");
  }
  check_gap_threshold(gap_threshold_s);
  return {.accel_lsb = accel_lsb,
          .gyro_lsb = gyro_lsb,
          .declared_axes = estimator::parse_imu_axes(imu_axes),
          .imu_axes = imu_axes,
          .gap_threshold_s = gap_threshold_s,
          .progress = progress,
          .file_size = progress && std::filesystem::exists(file) ? std::filesystem::file_size(file) : 0,
          .on_problem = on_problem};
}

namespace {

// What the log says of itself, into the result before anything is recorded.
void take_log_summary(const ImuLog& log, ImuLogImportResult& result) {
  result.imu_source = log.imu_source;
  result.reference_rows = log.reference.size();
  result.first_us = log.rows.front().t_us;
  result.last_us = log.rows.back().t_us;
}

// Every row, encoded as a frame at the settings' resolution, fed to the session; the link finished at the last. Returns
// how many samples had a value beyond the frame's range (clipped to it).
std::uint64_t record_rows(ImportSession& session, const std::vector<ImuRow>& rows,
                          const protocol::Calibration& calibration, const ImuLogSettings& settings,
                          ImuLogImportResult& result, ImportedSamples& samples) {
  std::vector<std::uint8_t> bytes;
  std::uint64_t clipped = 0;
  const auto progress = [&] {
    settings.progress({.bytes_read = settings.file_size, .bytes_total = settings.file_size, .samples = result.samples});
  };
  for (const ImuRow& row : rows) {
    if (beyond_frame_range(row.accel, settings.accel_lsb) || beyond_frame_range(row.gyro, settings.gyro_lsb)) {
      ++clipped;
    }
    bytes.clear();
    protocol::imu::encode({.seq = static_cast<std::uint16_t>(result.samples),
                           .device_time_us = row.t_us,
                           .payload = calibration.to_counts(row.accel, row.gyro, {}, 0.0)},
                          bytes);
    session.feed(bytes, ns(row.t_us), ns(row.t_us));
    ++result.samples;
    samples.add(static_cast<double>(row.t_us - result.first_us) * 1e-6, ns(row.t_us), row.accel, row.gyro);
    if (settings.progress && result.samples % kImportProgressEvery == 0) progress();
  }
  if (settings.progress) progress();
  const std::int64_t last = ns(result.last_us);
  session.finish_link(last, last);
  return clipped;
}

// The log's own events, then what the import left out, clipped or found damaged, at the last sample.
void record_import_events(ImportSession& session, ImuLog& log, std::uint64_t clipped,
                          const ImuLogImportResult& result) {
  const std::int64_t last = ns(result.last_us);
  const EventAt on_link{.link = session.link(), .mono_ns = last, .wall_ns = last};
  const EventAt on_session{.mono_ns = last, .wall_ns = last};
  for (LogEvent& e : log.events) {
    session.log_event({.mono_ns = ns(e.t_us), .wall_ns = ns(e.t_us)}, std::move(e.kind), std::move(e.detail));
  }
  const std::string records = log.imu_source + " records";
  for (const auto& [reason, count] : log.skipped) {
    session.report({.kind = ProblemKind::skipped, .count = count, .what = records, .why = reason}, on_link,
                   log.file + ": " + std::to_string(count) + " " + records + ": " + reason);
  }
  for (const auto& [reason, count] : log.reference_skipped) {
    session.report({.kind = ProblemKind::skipped, .count = count, .what = "reference rows", .why = reason}, on_session,
                   log.file + ": " + std::to_string(count) + " reference rows: " + reason);
  }
  if (clipped > 0) {
    session.report(
        {.kind = ProblemKind::clipped, .count = clipped, .what = "samples", .why = "beyond the frames' range"}, on_link,
        log.file + ": " + std::to_string(clipped) + " samples beyond the frames' range, clipped");
  }
  if (log.damage) {
    session.report({.kind = ProblemKind::damaged,
                    .count = 1,
                    .what = "stretch of " + log.file,
                    .why = *log.damage + "; everything before it is imported"},
                   on_session,
                   log.file + ": read up to the damage, " + *log.damage + "; everything before it is imported");
  }
}

}  // namespace

void record_imu_log(store::Store& store, ImuLog log, const ImuLogSettings& settings, ImuLogImportResult& result) {
  const auto calibration = import_calibration(settings.accel_lsb, settings.gyro_lsb);
  take_log_summary(log, result);

  ImportSession session(
      store, {.kind = "import", .source = log.source, .config = log.config, .started_wall_ns = ns(result.first_us)},
      {.recorded = {"imu0", protocol::WireFormat::imubridge, calibration, settings.imu_axes}, .device = log.device},
      settings.on_problem);
  result.session = session.id();
  ImportedSamples samples;
  const std::uint64_t clipped = record_rows(session, log.rows, calibration, settings, result, samples);
  for (const auto& row : log.reference) store.append_reference(result.session, row);

  record_import_events(session, log, clipped, result);
  const std::int64_t last = ns(result.last_us);
  ImportChecks checks = session.end(samples, settings.gap_threshold_s, samples.t_ns.front(), settings.declared_axes,
                                    {.link = session.link(), .mono_ns = last, .wall_ns = last},
                                    std::max(last, session.latest_event_ns()));
  result.gaps = std::move(checks.gaps);
  result.axes = std::move(checks.axes);
}

}  // namespace imubridge::importers
