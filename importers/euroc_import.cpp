#include "importers/euroc_import.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <utility>

#include "importers/import_session.hpp"
#include "importers/log_import.hpp"
#include "importers/position_derivative.hpp"
#include "protocol/imu_frame.hpp"
#include "replay/text_table.hpp"

namespace imubridge::importers {
namespace {

namespace fs = std::filesystem;

std::ifstream open_input(const fs::path& path) {
  if (!fs::is_regular_file(path)) throw std::invalid_argument(path.string() + ": no such file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::invalid_argument(path.string() + ": cannot be read");
  return in;
}

std::string no_rows_message(const fs::path& file, const replay::LinesByReason& skipped) {
  std::string message = file.string() + ": no usable rows";
  for (const auto& line : skipped.summary()) message += "; " + line;
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
std::vector<store::ReferenceRow> read_reference(const ReferenceFile& file, replay::LinesByReason& skipped) {
  std::ifstream in = open_input(file.path);
  const bool tum = file.format == ReferenceFormat::tum;
  const replay::TableLayout layout = tum ? replay::TableLayout{' ', 9, 8, 8}
                                         : replay::TableLayout{',', 0, 11, std::numeric_limits<std::size_t>::max()};
  std::vector<store::ReferenceRow> rows;
  replay::read_table(
      in, layout,
      [&](const replay::TableRow& row) -> std::optional<std::string> {
        const auto& v = row.values;
        const auto q = tum ? ned_attitude(v[6], v[3], v[4], v[5]) : ned_attitude(v[3], v[4], v[5], v[6]);
        if (!q) return "quaternion not of unit length";
        auto& r = rows.emplace_back(
            store::ReferenceRow{.t_ns = row.t_ns, .position = ned_from_zup(v[0], v[1], v[2]), .quat_wxyz = *q});
        if (!tum) r.velocity = ned_from_zup(v[7], v[8], v[9]);
        return std::nullopt;
      },
      skipped);
  if (rows.empty()) throw std::invalid_argument(no_rows_message(file.path, skipped));
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
  std::snprintf(text, sizeof text, "beyond +-%g %s", lsb * std::numeric_limits<std::int16_t>::max(), unit);
  return text;
}

// Each reason's rows as a problem of `kind`, stored at `at`; `stored_suffix` ends the reason in the event's detail.
void report_lines(ImportSession& session, const EventAt& at, ProblemKind kind, const fs::path& file,
                  const replay::LinesByReason& lines, const std::string& stored_suffix = "") {
  for (const auto& [reason, numbers] : lines.lines) {
    const bool one = numbers.size() == 1;
    session.report({.kind = kind,
                    .count = numbers.size(),
                    .what = (one ? "row of " : "rows of ") + file.string(),
                    .why = reason,
                    .where = (one ? "line " : "lines ") + replay::format_ranges(numbers)},
                   at, file.string() + ": " + replay::LinesByReason::describe(reason + stored_suffix, numbers));
  }
}

// The reference file named, else EuRoC's ground truth when the dataset has one.
std::optional<ReferenceFile> reference_file(const EurocImportOptions& options) {
  std::optional<ReferenceFile> reference = options.reference;
  if (const fs::path gt = options.dir / "mav0" / "state_groundtruth_estimate0" / "data.csv";
      !reference && fs::exists(gt)) {
    reference = ReferenceFile{gt, ReferenceFormat::euroc_gt};
  }
  return reference;
}

nlohmann::json session_config(const EurocImportOptions& options, const std::optional<ReferenceFile>& reference,
                              bool velocity_derived) {
  return {{"import",
           {{"format", "euroc"},
            {"dir", options.dir.string()},
            {"reference", reference ? reference->path.string() : ""},
            {"velocity_derived", velocity_derived},
            {"accel_lsb", options.accel_lsb},
            {"gyro_lsb", options.gyro_lsb}}}};
}

// Rows skipped or clipped, by line and reason, as the files were read.
struct RowProblems {
  replay::LinesByReason imu_skipped, clipped, reference_skipped;
};

// The IMU rows, as read_table hands them, encoded as frames fed to the import's session. The session begins with the
// first usable row, so a file without one leaves nothing behind. The dataset's timestamps (Unix time, ns) serve as
// both receive clocks; the device clock starts at 0 with the first row.
class ImuRecording {
 public:
  ImuRecording(store::Store& store, const EurocImportOptions& options, const protocol::Calibration& calibration,
               nlohmann::json config, EurocImportResult& result, replay::LinesByReason& clipped)
      : store_(store),
        options_(options),
        calibration_(calibration),
        config_(std::move(config)),
        result_(result),
        clipped_(clipped),
        accel_beyond_("accel " + range_text(options.accel_lsb, "m/s^2")),
        gyro_beyond_("gyro " + range_text(options.gyro_lsb, "rad/s")) {}

  void add(const replay::TableRow& row) {
    if (!session_) begin(row.t_ns);
    const auto& v = row.values;  // EuRoC's order: gyro xyz, then accel xyz
    const std::array gyro{v[0], v[1], v[2]}, accel{v[3], v[4], v[5]};
    if (beyond_frame_range(accel, options_.accel_lsb)) clipped_.add(row.line, accel_beyond_);
    if (beyond_frame_range(gyro, options_.gyro_lsb)) clipped_.add(row.line, gyro_beyond_);
    const std::uint64_t since_t0 = replay::elapsed_ns(t0_, row.t_ns);
    bytes_.clear();
    protocol::imu::encode({.seq = static_cast<std::uint16_t>(result_.imu.rows),
                           .device_time_us = since_t0 / 1000 + (since_t0 % 1000 >= 500 ? 1 : 0),
                           .payload = calibration_.to_counts(accel, gyro, {}, 0.0)},
                          bytes_);
    session_->feed(bytes_, row.t_ns, row.t_ns);
    ++result_.imu.rows;
    last_t_ = row.t_ns;
    samples_.add(static_cast<double>(since_t0) * 1e-9, row.t_ns, accel, gyro);
  }

  bool begun() const { return session_.has_value(); }
  // Finishes the link at the last row's time.
  void finish() { session_->finish_link(last_t_, last_t_); }
  ImportSession& session() { return *session_; }
  std::int64_t first_t() const { return t0_; }
  std::int64_t last_t() const { return last_t_; }
  const ImportedSamples& samples() const { return samples_; }

 private:
  void begin(std::int64_t t0) {
    t0_ = t0;
    session_.emplace(
        store_,
        pipeline::SessionStart{.kind = "import",
                               .source = "EuRoC dataset " + options_.dir.string(),
                               .config = config_,
                               .started_wall_ns = t0_},
        pipeline::SessionLink{.recorded = {"imu0", protocol::WireFormat::imubridge, calibration_, options_.imu_axes},
                              .device = "EuRoC imu0, " + result_.imu.path.string()},
        options_.on_problem);
    result_.session = session_->id();
  }

  store::Store& store_;
  const EurocImportOptions& options_;
  const protocol::Calibration& calibration_;
  const nlohmann::json config_;
  EurocImportResult& result_;
  replay::LinesByReason& clipped_;
  const std::string accel_beyond_, gyro_beyond_;
  std::optional<ImportSession> session_;
  std::int64_t t0_ = 0, last_t_ = 0;
  std::vector<std::uint8_t> bytes_;
  ImportedSamples samples_;
};

// How far reading the IMU file is, by its stream's position.
void report_progress(std::ifstream& imu, std::uint64_t imu_size, std::uint64_t rows,
                     const ImportProgressCallback& progress) {
  const std::streamoff at = imu.tellg();
  if (at >= 0) {
    progress(
        {.bytes_read = std::min(static_cast<std::uint64_t>(at), imu_size), .bytes_total = imu_size, .samples = rows});
  }
}

// What the import left out or clipped, as problems at the last row.
void report_problems(ImuRecording& recording, const EurocImportResult& result, const RowProblems& problems) {
  ImportSession& session = recording.session();
  const std::int64_t t = recording.last_t();
  const EventAt on_link{.link = session.link(), .mono_ns = t, .wall_ns = t};
  report_lines(session, on_link, ProblemKind::skipped, result.imu.path, problems.imu_skipped);
  report_lines(session, on_link, ProblemKind::clipped, result.imu.path, problems.clipped, ", clipped");
  if (result.reference) {
    report_lines(session, {.mono_ns = t, .wall_ns = t}, ProblemKind::skipped, result.reference->path,
                 problems.reference_skipped);
  }
}

// The IMU file's rows recorded, its progress reported as it is read.
void read_imu(std::ifstream& imu, const EurocImportOptions& options, ImuRecording& recording,
              const EurocImportResult& result, replay::LinesByReason& skipped) {
  const std::uint64_t imu_size = options.progress ? fs::file_size(result.imu.path) : 0;
  replay::read_table(
      imu, {',', 0, 7, 7},
      [&](const replay::TableRow& row) -> std::optional<std::string> {
        recording.add(row);
        if (options.progress && result.imu.rows % kImportProgressEvery == 0 && !imu.eof()) {
          report_progress(imu, imu_size, result.imu.rows, options.progress);
        }
        return std::nullopt;
      },
      skipped);
  if (!recording.begun()) throw std::invalid_argument(no_rows_message(result.imu.path, skipped));
  if (options.progress) options.progress({.bytes_read = imu_size, .bytes_total = imu_size, .samples = result.imu.rows});
}

// The options checked before anything is read: the declared IMU axes.
estimator::ImuAxes checked_options(const EurocImportOptions& options, const protocol::Calibration& calibration) {
  if (!calibration.valid() || options.accel_lsb <= 0 || options.gyro_lsb <= 0) {
    throw std::invalid_argument("the accelerometer and gyro resolutions must be positive and finite");
  }
  const estimator::ImuAxes declared_axes = estimator::parse_imu_axes(options.imu_axes);
  check_gap_threshold(options.gap_threshold_s);
  return declared_axes;
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
  const estimator::ImuAxes declared_axes = checked_options(options, calibration);
  EurocImportResult result;
  RowProblems problems;
  result.imu.path = options.dir / "mav0" / "imu0" / "data.csv";
  std::ifstream imu = open_input(result.imu.path);
  const std::optional<ReferenceFile> reference = reference_file(options);
  std::vector<store::ReferenceRow> reference_rows;
  if (reference) {
    reference_rows = read_reference(*reference, problems.reference_skipped);
    result.reference = ImportedFile{.path = reference->path, .rows = reference_rows.size()};
    result.velocity_derived = reference->format == ReferenceFormat::tum;
  }

  ImuRecording recording(store, options, calibration, session_config(options, reference, result.velocity_derived),
                         result, problems.clipped);
  read_imu(imu, options, recording, result, problems.imu_skipped);
  recording.finish();
  for (const auto& row : reference_rows) store.append_reference(result.session, row);
  report_problems(recording, result, problems);
  const std::int64_t last_t = recording.last_t();
  ImportChecks checks =
      recording.session().end(recording.samples(), options.gap_threshold_s, recording.first_t(), declared_axes,
                              {.link = recording.session().link(), .mono_ns = last_t, .wall_ns = last_t}, last_t);
  result.gaps = std::move(checks.gaps);
  result.axes = std::move(checks.axes);
  return result;
}

}  // namespace imubridge::importers
