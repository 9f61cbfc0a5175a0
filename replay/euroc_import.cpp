#include "replay/euroc_import.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <utility>

#include "pipeline/record_and_decode.hpp"
#include "pipeline/recorded_session.hpp"
#include "pipeline/session_engine.hpp"
#include "protocol/imu_frame.hpp"
#include "replay/log_import.hpp"
#include "replay/position_derivative.hpp"

namespace imubridge::replay {
namespace {

namespace fs = std::filesystem;

std::ifstream open_input(const fs::path& path) {
  if (!fs::is_regular_file(path)) throw std::invalid_argument(path.string() + ": no such file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::invalid_argument(path.string() + ": cannot be read");
  return in;
}

std::string no_rows_message(const ImportedFile& file) {
  std::string message = file.path.string() + ": no usable rows";
  for (const auto& line : file.skipped.summary()) message += "; " + line;
  return message;
}

// EuRoC's world has z up: NED is it turned 180 degrees about x, (x, y, z) -> (x, -y, -z). `sim --euroc` writes the
// inverse.
std::array<double, 3> ned_from_zup(double x, double y, double z) { return {x, -y, -z}; }

// The attitude sensor -> NED from EuRoC's q_RS (sensor -> z-up world): the 180-degree turn about x, (0, 1, 0, 0),
// composed in front: (0, 1, 0, 0) * (w, x, y, z) = (-x, w, -z, y). Nothing if q is not (nearly) a unit quaternion.
std::optional<std::array<double, 4>> ned_attitude(double w, double x, double y, double z) {
  const double norm = std::sqrt(w * w + x * x + y * y + z * z);
  if (!(std::abs(norm - 1) <= 1e-2)) return std::nullopt;  // files round to ~6 digits; more is not a rotation
  return std::array{-x / norm, w / norm, -z / norm, y / norm};
}

// The rows in the estimator's conventions; a TUM file's velocities derived from its positions.
std::vector<store::ReferenceRow> read_reference(const ReferenceFile& file, ImportedFile& report) {
  std::ifstream in = open_input(file.path);
  const bool tum = file.format == ReferenceFormat::tum;
  const TableLayout layout =
      tum ? TableLayout{' ', 9, 8, 8} : TableLayout{',', 0, 11, std::numeric_limits<std::size_t>::max()};
  std::vector<store::ReferenceRow> rows;
  read_table(
      in, layout,
      [&](const TableRow& row) -> std::optional<std::string> {
        const auto& v = row.values;
        const auto q = tum ? ned_attitude(v[6], v[3], v[4], v[5]) : ned_attitude(v[3], v[4], v[5], v[6]);
        if (!q) return "quaternion not of unit length";
        auto& r = rows.emplace_back(
            store::ReferenceRow{.t_ns = row.t_ns, .position = ned_from_zup(v[0], v[1], v[2]), .quat_wxyz = *q});
        if (!tum) r.velocity = ned_from_zup(v[7], v[8], v[9]);
        return std::nullopt;
      },
      report.skipped);
  report.rows = rows.size();
  if (rows.empty()) throw std::invalid_argument(no_rows_message(report));
  if (tum) {
    std::vector<std::int64_t> t;
    std::vector<Eigen::Vector3d> p;
    for (const auto& r : rows) {
      t.push_back(r.t_ns);
      p.emplace_back(r.position[0], r.position[1], r.position[2]);
    }
    const auto velocity = velocity_from_positions(t, p);
    for (std::size_t i = 0; i < rows.size(); ++i) {
      if (velocity[i]) rows[i].velocity = std::array{velocity[i]->x(), velocity[i]->y(), velocity[i]->z()};
    }
  }
  return rows;
}

std::string range_text(double lsb, const char* unit) {
  char text[64];
  std::snprintf(text, sizeof text, "beyond +-%g %s, clipped", lsb * std::numeric_limits<std::int16_t>::max(), unit);
  return text;
}

void record_lines(store::Store& store, std::int64_t session, std::optional<std::int64_t> link, std::int64_t t_ns,
                  const char* kind, const fs::path& file, const LinesByReason& lines) {
  for (const auto& [reason, at] : lines.lines) {
    store.append_event(session, {.link_id = link,
                                 .mono_ns = t_ns,
                                 .wall_ns = t_ns,
                                 .kind = kind,
                                 .count = static_cast<std::int64_t>(at.size()),
                                 .detail = file.string() + ": " + LinesByReason::describe(reason, at)});
  }
}

}  // namespace

ReferenceFormat parse_reference_format(std::string_view name) {
  if (name == "tum") return ReferenceFormat::tum;
  if (name == "euroc-gt") return ReferenceFormat::euroc_gt;
  throw std::invalid_argument("unknown reference format \"" + std::string(name) + "\" (tum, euroc-gt)");
}

protocol::Calibration import_calibration(double accel_lsb, double gyro_lsb) {
  protocol::Calibration c;  // identity axes, zero offsets, unit scales for the absent magnetometer and temperature
  c.accel.scale.fill(accel_lsb);
  c.gyro.scale.fill(gyro_lsb);
  return c;
}

EurocImportResult import_euroc(store::Store& store, const EurocImportOptions& options) {
  const auto calibration = import_calibration(options.accel_lsb, options.gyro_lsb);
  if (!calibration.valid() || options.accel_lsb <= 0 || options.gyro_lsb <= 0) {
    throw std::invalid_argument("the accelerometer and gyro resolutions must be positive and finite");
  }
  const estimator::ImuAxes declared_axes = estimator::parse_imu_axes(options.imu_axes);
  check_gap_threshold(options.gap_threshold_s);
  EurocImportResult result;
  result.imu.path = options.dir / "mav0" / "imu0" / "data.csv";
  std::ifstream imu = open_input(result.imu.path);
  const std::uint64_t imu_size = options.progress ? fs::file_size(result.imu.path) : 0;
  std::optional<ReferenceFile> reference = options.reference;
  if (const fs::path gt = options.dir / "mav0" / "state_groundtruth_estimate0" / "data.csv";
      !reference && fs::exists(gt)) {
    reference = ReferenceFile{gt, ReferenceFormat::euroc_gt};
  }
  std::vector<store::ReferenceRow> reference_rows;
  if (reference) {
    result.reference = ImportedFile{.path = reference->path};
    reference_rows = read_reference(*reference, *result.reference);
    result.velocity_derived = reference->format == ReferenceFormat::tum;
  }

  nlohmann::json config = {{"import",
                            {{"format", "euroc"},
                             {"dir", options.dir.string()},
                             {"reference", reference ? reference->path.string() : ""},
                             {"velocity_derived", result.velocity_derived},
                             {"accel_lsb", options.accel_lsb},
                             {"gyro_lsb", options.gyro_lsb}}}};
  std::vector<double> axes_t;  // the rows as read, for the gravity check
  std::vector<std::int64_t> t_ns;  // and for the holes
  std::vector<Eigen::Vector3d> axes_accel, axes_gyro;
  // The session begins with the first usable row, so a file without one leaves nothing behind. The dataset's
  // timestamps (Unix time, ns) serve as both receive clocks; the device clock starts at 0 with the first row. The
  // frames go through the session engine without estimation: an import has no parameters (a replay estimates).
  pipeline::SessionEngine engine(nullptr);
  std::optional<pipeline::RecordAndDecode> recording;
  std::int64_t link = 0, t0 = 0, last_t = 0;
  std::vector<std::uint8_t> bytes;
  const std::string accel_beyond = "accel " + range_text(options.accel_lsb, "m/s^2");
  const std::string gyro_beyond = "gyro " + range_text(options.gyro_lsb, "rad/s");
  read_table(
      imu, {',', 0, 7, 7},
      [&](const TableRow& row) -> std::optional<std::string> {
        if (!recording) {
          t0 = row.t_ns;
          pipeline::RecordedSession recorded = pipeline::begin_recorded_session(
              store,
              {.kind = "import",
               .source = "EuRoC dataset " + options.dir.string(),
               .config = config,
               .started_wall_ns = t0},
              {{.recorded = {"imu0", protocol::WireFormat::imubridge, calibration, options.imu_axes},
                .device = "EuRoC imu0, " + result.imu.path.string()}});
          result.session = recorded.id;
          link = recorded.store_links[0];
          recording.emplace(std::move(recorded.recorders[0]));
        }
        const auto& v = row.values;  // EuRoC's order: gyro xyz, then accel xyz
        const std::array gyro{v[0], v[1], v[2]}, accel{v[3], v[4], v[5]};
        if (beyond_frame_range(accel, options.accel_lsb)) result.clipped.add(row.line, accel_beyond);
        if (beyond_frame_range(gyro, options.gyro_lsb)) result.clipped.add(row.line, gyro_beyond);
        const std::uint64_t since_t0 = elapsed_ns(t0, row.t_ns);
        bytes.clear();
        protocol::imu::encode({.seq = static_cast<std::uint16_t>(result.imu.rows),
                               .device_time_us = since_t0 / 1000 + (since_t0 % 1000 >= 500 ? 1 : 0),
                               .payload = calibration.to_counts(accel, gyro, {}, 0.0)},
                              bytes);
        engine.on_chunk(0, *recording, bytes, row.t_ns, row.t_ns);
        ++result.imu.rows;
        last_t = row.t_ns;
        axes_t.push_back(static_cast<double>(since_t0) * 1e-9);
        t_ns.push_back(row.t_ns);
        axes_accel.emplace_back(accel[0], accel[1], accel[2]);
        axes_gyro.emplace_back(gyro[0], gyro[1], gyro[2]);
        store.commit_if_due(std::chrono::steady_clock::now());
        if (options.progress && result.imu.rows % kImportProgressEvery == 0 && !imu.eof()) {
          const std::streamoff at = imu.tellg();
          if (at >= 0) {
            options.progress({.bytes_read = std::min(static_cast<std::uint64_t>(at), imu_size),
                              .bytes_total = imu_size,
                              .samples = result.imu.rows});
          }
        }
        return std::nullopt;
      },
      result.imu.skipped);
  if (!recording) throw std::invalid_argument(no_rows_message(result.imu));
  if (options.progress) options.progress({.bytes_read = imu_size, .bytes_total = imu_size, .samples = result.imu.rows});

  engine.finish_link(0, *recording, last_t, last_t);
  engine.finish();
  for (const auto& row : reference_rows) store.append_reference(result.session, row);
  record_lines(store, result.session, link, last_t, "import_skipped", result.imu.path, result.imu.skipped);
  record_lines(store, result.session, link, last_t, "import_clipped", result.imu.path, result.clipped);
  if (result.reference) {
    record_lines(store, result.session, std::nullopt, last_t, "import_skipped", result.reference->path,
                 result.reference->skipped);
  }
  result.gaps = find_gaps(t_ns, options.gap_threshold_s, t0);
  append_gap_events(store, result.session, link, result.gaps);
  result.axes = estimator::resolve_axes(declared_axes, estimator::detect_up(axes_t, axes_accel, axes_gyro));
  if (result.axes.mismatch) {
    store.append_event(result.session, {.link_id = link,
                                        .mono_ns = last_t,
                                        .wall_ns = last_t,
                                        .kind = "imu_axes_mismatch",
                                        .detail = *result.axes.mismatch});
  }
  pipeline::end_recorded_session(store, result.session, last_t);
  return result;
}

}  // namespace imubridge::replay
