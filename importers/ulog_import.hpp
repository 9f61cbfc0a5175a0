#pragma once
// `imubridge import ulog`: a PX4 ULog file as a session of kind "import", as `import euroc` does it: the raw IMU
// (sensor_combined, else sensor_accel with sensor_gyro) re-encoded as imubridge frames and recorded through the
// session engine and its LinkRecorder, the vehicle's attitude and local position as the reference trajectory, logged
// strings, dropouts and holes as events, the parameters and info in the session's config. docs/replay.md, "PX4 ULog".
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "estimator/imu_axes.hpp"
#include "importers/import_problem.hpp"
#include "importers/import_progress.hpp"
#include "importers/log_import.hpp"
#include "store/store.hpp"

namespace imubridge::importers {

struct UlogImportOptions {
  std::filesystem::path file;
  // The frames' resolution: +-164 m/s^2 (an MPU9250's +-16 g) and +-36 rad/s (its +-2000 deg/s) as int16 counts.
  double accel_lsb = 5e-3;                         // m/s^2 per count
  double gyro_lsb = 1.1e-3;                        // rad/s per count
  std::string imu_axes = "frd";                    // PX4 reports its IMU in the body's FRD axes
  bool reference = true;                           // vehicle_attitude + vehicle_local_position into the reference table
  double gap_threshold_s = kDefaultGapThresholdS;  // the IMU stopping for longer is a `gap` event
  // Hears how far the import is: the file's bytes while it is parsed, then the samples as they are recorded (at
  // bytes_read == bytes_total). Optional.
  ImportProgressCallback progress{};
  // Hears each record skipped, value clipped and stretch damaged (ImportProblem). Optional.
  ProblemCallback on_problem{};
};

struct UlogImportResult : ImuLogImportResult {
  std::uint64_t log_events = 0;
  std::uint64_t dropouts = 0;
  std::uint64_t dropout_ms = 0;
  bool data_appended = false;
  std::uint64_t appended_messages = 0;
  // When the vehicle flew, from PX4's land detector (vehicle_land_detected.landed): [takeoff, landing) in ULog µs,
  // a flight still going at the log's end closing at its last record. Unset when the log has no land detector, so
  // whether it flew is unknown (diagnose can still find the flight from the rotors' vibration).
  struct Interval {
    std::uint64_t from_us = 0, to_us = 0;
  };
  std::optional<std::vector<Interval>> airborne;
};

// Throws std::invalid_argument (ulog::ParseError among them), before writing anything, when the file cannot be read
// as a ULog, has no IMU topic with a usable record, or the options are invalid.
UlogImportResult import_ulog(store::Store& store, const UlogImportOptions& options);

}  // namespace imubridge::importers
