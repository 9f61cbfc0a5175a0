#pragma once
// `imubridge import tlog`: a MAVLink telemetry log as a session of kind "import". Each record's frame is a chunk of a
// link of wire format mavlink, received at the record's time, so the session holds exactly the bytes a live MAVLink
// link would have received and replay decodes them as it would; the link's samples come from one IMU (the one sending
// the most messages), LOCAL_POSITION_NED with ATTITUDE_QUATERNION (else ATTITUDE) is the reference trajectory,
// STATUSTEXT, gaps in the log's time, holes in the IMU's samples and damage are events. docs/replay.md, "MAVLink
// telemetry logs".
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>

#include "estimator/imu_axes.hpp"
#include "importers/import_problem.hpp"
#include "importers/import_progress.hpp"
#include "importers/log_import.hpp"
#include "store/store.hpp"

namespace imubridge::importers {

struct TlogImportOptions {
  std::filesystem::path file;
  std::string imu_axes = "frd";  // MAVLink's IMU messages are in the body's FRD axes
  bool reference = true;         // LOCAL_POSITION_NED + ATTITUDE_QUATERNION or ATTITUDE into the reference table
  // RAW_IMU carries counts: it is a candidate IMU only given both resolutions (ArduPilot sends mG and mrad/s:
  // 9.80665e-3 m/s^2 and 1e-3 rad/s per count). Its magnetometer counts are taken as mgauss.
  std::optional<double> accel_lsb{}, gyro_lsb{};
  // Only this message's IMUs are candidates ("SCALED_IMU2", ...); default: every IMU message.
  std::optional<std::string> imu_message{};
  double gap_threshold_s = kDefaultGapThresholdS;  // the IMU stopping for longer is a `gap` event
  // Hears how far the recording of the file's records is (bytes up to the end of the last record recorded). Optional.
  ImportProgressCallback progress{};
  // Hears each message skipped, value clipped and stretch damaged (ImportProblem). Optional.
  ProblemCallback on_problem{};
};

// What a tlog's import made; what it skipped, clipped or found damaged went to `on_problem`.
struct TlogImportResult {
  std::int64_t session = 0;
  std::string imu_source;                             // protocol::mavlink::describe() of the IMU imported
  std::map<std::string, std::uint64_t> imu_messages;  // every IMU in the log (as imu_source says it): its messages
  std::uint64_t samples = 0;                          // IMU samples imported
  std::uint64_t records = 0;                          // records read (each one frame, a chunk of the link)
  std::uint64_t unverified = 0;                       // of them, valid frames nothing here can check (kept as they are)
  std::optional<std::string> unverified_summary;      // what they are: unknown ids, known ids of another layout
  std::string reference_source;                       // "LOCAL_POSITION_NED + ATTITUDE_QUATERNION", ... ; empty: none
  std::uint64_t reference_rows = 0;
  std::uint64_t log_events = 0;             // STATUSTEXT messages
  std::uint64_t log_gaps = 0;               // stretches without a record over kTlogGapUs
  double log_gap_s = 0;                     // their length, summed
  Gaps gaps;                                // holes in the imported IMU's samples
  std::uint64_t time_back = 0;              // records stamped before the one before them
  std::uint64_t first_us = 0, last_us = 0;  // the first and last record's times, µs since the UNIX epoch
  estimator::AxesResolution axes;
};

// A stretch of the log's time without any record longer than this is a `log_gap` event.
inline constexpr std::uint64_t kTlogGapUs = 2'000'000;

// Throws std::invalid_argument (tlog::ParseError among them), before writing anything, when the file cannot be read
// as a tlog, holds no IMU message that gives samples, or the options are invalid.
TlogImportResult import_tlog(store::Store& store, const TlogImportOptions& options);

}  // namespace imubridge::importers
