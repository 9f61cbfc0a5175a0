#pragma once
// `imubridge import euroc`: an EuRoC/ASL dataset as a session of kind "import". The IMU rows are re-encoded as
// imubridge frames and recorded through the session engine and its LinkRecorder, so the session starts from bytes
// like any recorded one and replays the same way; the reference trajectory goes to the reference table in the
// estimator's conventions (NED, attitude body -> NED). Conventions, calibration and the clock: docs/replay.md.
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string_view>

#include "estimator/imu_axes.hpp"
#include "importers/import_problem.hpp"
#include "importers/import_progress.hpp"
#include "importers/log_import.hpp"
#include "protocol/calibration.hpp"
#include "store/store.hpp"

namespace imubridge::importers {

enum class ReferenceFormat {
  tum,       // "t x y z qx qy qz qw", t in seconds, space separated: positions only
  euroc_gt,  // EuRoC's state_groundtruth_estimate0/data.csv: t [ns], p xyz, q wxyz, v xyz, biases (ignored)
};
// Throws std::invalid_argument naming the valid formats.
ReferenceFormat parse_reference_format(std::string_view name);

struct ReferenceFile {
  std::filesystem::path path;
  ReferenceFormat format = ReferenceFormat::tum;
};

struct EurocImportOptions {
  std::filesystem::path dir;                 // the dataset: holds mav0/imu0/data.csv
  std::optional<ReferenceFile> reference{};  // default: mav0/state_groundtruth_estimate0/data.csv when it exists
  // The frames' resolution. int16 counts then reach +-65.5 m/s^2 and +-6.55 rad/s: EuRoC's MH_01 peaks at 60 m/s^2
  // and 4 rad/s. Values beyond are clipped and reported.
  double accel_lsb = 2e-3;  // m/s^2 per count
  double gyro_lsb = 2e-4;   // rad/s per count
  // How the IMU's axes sit in the body (estimator::parse_imu_axes), recorded in the link's config. EuRoC's ADIS16448
  // is mounted x up: "x-up"; "auto" detects it from gravity whenever the session is read.
  std::string imu_axes = "auto";
  double gap_threshold_s = kDefaultGapThresholdS;  // the IMU stopping for longer is a `gap` event
  // Hears how far reading the IMU file (mav0/imu0/data.csv) is. Optional.
  ImportProgressCallback progress{};
  // Hears each reason rows were skipped or clipped for, with their lines (ImportProblem). Optional.
  ProblemCallback on_problem{};
};

struct ImportedFile {
  std::filesystem::path path;
  std::uint64_t rows = 0;  // rows imported
};

// What the import made; what it skipped or clipped went to `on_problem`.
struct EurocImportResult {
  std::int64_t session = 0;
  ImportedFile imu;
  std::optional<ImportedFile> reference;
  bool velocity_derived = false;   // the reference had positions only: velocity_from_positions() supplied it
  estimator::AxesResolution axes;  // the declared axes checked against gravity in the imported rows
  Gaps gaps;                       // holes in the IMU's data
};

// The calibration imported frames are encoded with: the resolutions, no offsets, IMU axes as in the file. EuRoC has
// no magnetometer or temperature: their counts are 0 (they decode as 0 uT, 0 C).
protocol::Calibration import_calibration(double accel_lsb, double gyro_lsb);

// Skipped rows and clipped values are problems (on_problem, and events of kind "import_skipped" and
// "import_clipped"), holes in the IMU's data "gap" events, and declared axes that gravity contradicts as one of kind
// "imu_axes_mismatch". Throws std::invalid_argument, before writing anything, when a file is missing or has no usable
// row, or the IMU axes do not parse.
EurocImportResult import_euroc(store::Store& store, const EurocImportOptions& options);

}  // namespace imubridge::importers
