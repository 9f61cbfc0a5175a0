#pragma once
// `imubridge import dataflash`: an ArduPilot DataFlash log (.bin) as a session of kind "import", as `import ulog` does
// it (importers/log_import.hpp): one IMU instance's samples (IMU, or ACC with GYR where they are logged faster)
// re-encoded as imubridge frames and recorded through the session engine, the EKF's position, velocity and attitude
// as the reference trajectory, MSG, MODE and arming as events, the parameters in the session's config.
// docs/replay.md, "ArduPilot DataFlash".
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>

#include "importers/import_problem.hpp"
#include "importers/import_progress.hpp"
#include "importers/log_import.hpp"
#include "store/store.hpp"

namespace imubridge::importers {

struct DataflashImportOptions {
  std::filesystem::path file;
  // The frames' resolution, as for a ULog: +-164 m/s^2 and +-36 rad/s as int16 counts (ArduPilot's IMUs are the same
  // MPU/ICM/BMI parts at +-16 g and +-2000 deg/s).
  double accel_lsb = 5e-3;        // m/s^2 per count
  double gyro_lsb = 1.1e-3;       // rad/s per count
  std::string imu_axes = "frd";   // ArduPilot logs its IMUs in the body's FRD axes
  bool reference = true;          // the EKF's position, velocity and attitude into the reference table
  std::optional<unsigned> imu{};  // the IMU instance (0: IMU or ACC1/GYR1 or I = 0); default 0, else the lowest
  double gap_threshold_s = kDefaultGapThresholdS;  // the IMU stopping for longer is a `gap` event
  // Hears how far the import is: the file's bytes while it is parsed, then the samples as they are recorded. Optional.
  ImportProgressCallback progress{};
  // Hears each record skipped, value clipped and stretch damaged (ImportProblem). Optional.
  ProblemCallback on_problem{};
};

struct DataflashImportResult : ImuLogImportResult {
  unsigned instance = 0;                    // the IMU instance imported
  std::map<unsigned, std::string> imus;     // every IMU instance in the log: "IMU2: 11916"
  std::string reference_source;             // "EKF1 (attitude from its Roll, Pitch, Yaw)", ...; empty: none
  std::uint64_t log_events = 0;             // MSG records
  std::uint64_t mode_changes = 0;           // MODE records
  std::uint64_t arming_changes = 0;         // armed and disarmed, from EV or ARM
  std::uint64_t land_detector_changes = 0;  // takeoffs and landings, from EV 28 and 18
  std::uint64_t params = 0;                 // parameters (PARM names)
};

// Throws std::invalid_argument (dataflash::ParseError among them), before writing anything, when the file cannot be
// read as a DataFlash log, has no IMU records with a usable sample (or not the instance asked for), or the options are
// invalid.
DataflashImportResult import_dataflash(store::Store& store, const DataflashImportOptions& options);

}  // namespace imubridge::importers
