#pragma once
// What the imports of on-board flight logs (`import ulog`, `import dataflash`) share: a log's IMU rows, reference and
// events recorded as a session of kind "import" through the session engine, and the pieces each reader uses to get
// them (accelerometer paired with gyro, attitude interpolated); and, for every import (euroc and tlog too), the holes
// in the IMU's data as `gap` events. docs/replay.md.
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "estimator/imu_axes.hpp"
#include "importers/import_problem.hpp"
#include "importers/import_progress.hpp"
#include "store/store.hpp"

namespace imubridge::importers {

// The IMU stopping for longer than this is a hole in the data: a `gap` event. 0.5 s is 25 periods of the slowest IMU
// logs seen (ArduPilot's 50 Hz), far above any logger's write stall (PX4 reports those as dropouts of tens of ms), and
// already long enough for velocity integrated across it to be off by metres per m/s^2 of bias.
inline constexpr double kDefaultGapThresholdS = 0.5;

struct Gap {
  std::int64_t from_ns = 0, to_ns = 0;  // the last sample before the hole and the first after it
  // In doubles: a log's times can be anything, and their difference must not overflow.
  double seconds() const { return (static_cast<double>(to_ns) - static_cast<double>(from_ns)) * 1e-9; }
};

struct Gaps {
  double threshold_s = kDefaultGapThresholdS;
  std::int64_t session_start_ns = 0;  // what the spans in the events' details are counted from
  std::vector<Gap> holes{};
  double seconds() const;
};

// The holes over `threshold_s` between consecutive times (increasing). Throws std::invalid_argument unless
// threshold_s is positive and finite.
Gaps find_gaps(std::span<const std::int64_t> t_ns, double threshold_s, std::int64_t session_start_ns);
// Each hole as a `gap` event on `link` at its start, its span in session time in the detail.
void append_gap_events(store::Store& store, std::int64_t session, std::int64_t link, const Gaps& gaps);
// Throws std::invalid_argument naming the option when the threshold is not positive and finite.
void check_gap_threshold(double threshold_s);

// The IMU's samples as an import writes them: their times, for the holes, and their values, for the check of the
// declared axes against gravity.
struct ImportedSamples {
  std::vector<double> t{};  // s since the first, as the import counts it
  std::vector<std::int64_t> t_ns{};
  std::vector<Eigen::Vector3d> accel{}, gyro{};

  void add(double t_s, std::int64_t at_ns, const std::array<double, 3>& a, const std::array<double, 3>& g);
  // The holes over `threshold_s` (find_gaps), each as a `gap` event on `link` (append_gap_events).
  Gaps record_gaps(store::Store& store, std::int64_t session, std::int64_t link, double threshold_s,
                   std::int64_t session_start_ns) const;
  // The declared axes checked against the gravity in these samples.
  estimator::AxesResolution resolve_axes(const estimator::ImuAxes& declared) const;
};

struct ImuRow {
  std::uint64_t t_us = 0;
  std::array<double, 3> accel{}, gyro{};
};

using TimedVector = std::pair<std::uint64_t, std::array<double, 3>>;  // µs, value

// The columns `names` of a log's table (a ULog topic's leaves, a DataFlash message's fields) as `find` looks them up,
// or nothing if any is missing.
template <std::size_t N, typename Table>
std::optional<std::array<std::size_t, N>> columns(const Table& table,
                                                  std::optional<std::size_t> (Table::*find)(std::string_view) const,
                                                  const std::array<const char*, N>& names) {
  std::array<std::size_t, N> out{};
  for (std::size_t i = 0; i < N; ++i) {
    const auto at = (table.*find)(names[i]);
    if (!at) return std::nullopt;
    out[i] = *at;
  }
  return out;
}

// Three columns of a record, as the table's value(record, column) reads them.
template <typename Table>
std::array<double, 3> vec3(const Table& table, std::size_t record, const std::array<std::size_t, 3>& at) {
  return {table.value(record, at[0]), table.value(record, at[1]), table.value(record, at[2])};
}

bool finite(const std::array<double, 3>& v);
// Whether `si` is beyond what an int16 count of `lsb` holds (Calibration::to_counts then saturates).
bool beyond_frame_range(const std::array<double, 3>& si, double lsb);

// Appends `row` when it is after the last row (a damaged or odd log may step back), else counts it as skipped.
void append_in_order(const ImuRow& row, std::vector<ImuRow>& rows, std::map<std::string, std::uint64_t>& skipped);

// Each gyro sample with the accelerometer interpolated linearly to its time, never across more than kMaxAccelGapUs;
// both series in increasing time.
std::vector<ImuRow> pair_accel_with_gyro(const std::vector<TimedVector>& accel, const std::vector<TimedVector>& gyro,
                                         std::map<std::string, std::uint64_t>& skipped);
inline constexpr std::uint64_t kMaxAccelGapUs = 100'000;

// An attitude (body -> NED) over time, read at any time by slerp between the two samples around it.
class AttitudeSeries {
 public:
  // Samples not after the last are ignored; a quaternion not of unit length (also NaN: a filter not yet initialised)
  // is counted in `skipped` and left out.
  void add(std::uint64_t t_us, const Eigen::Quaterniond& q, std::map<std::string, std::uint64_t>& skipped);
  // Nothing when no two samples at most kMaxAttitudeGapUs apart bracket t (or none is at t).
  std::optional<Eigen::Quaterniond> at(std::uint64_t t_us);
  bool empty() const { return samples_.empty(); }

 private:
  std::vector<std::pair<std::uint64_t, Eigen::Quaterniond>> samples_;
  std::size_t k_ = 0;  // where the last look-up found its bracket: look-ups come in increasing time
};
inline constexpr std::uint64_t kMaxAttitudeGapUs = 500'000;

// Roll, pitch, yaw (ZYX, radians) as the quaternion body -> NED.
Eigen::Quaterniond attitude_from_euler(double roll, double pitch, double yaw);

// An event of the whole session at a log's time.
struct LogEvent {
  std::uint64_t t_us = 0;
  std::string kind;
  std::string detail;
};

// What a flight log gives for its session, in the log's clock (µs since the autopilot booted).
struct ImuLog {
  std::string source{};        // the session's, for people: "PX4 ULog FILE"
  std::string file{};          // as given, for the events' details
  std::string imu_source{};    // which of the log's IMUs: "sensor_combined", "IMU2"
  std::string device{};        // the link's, for people
  nlohmann::json config{};     // the session's config snapshot
  std::vector<ImuRow> rows{};  // increasing in time, at least one
  std::vector<store::ReferenceRow> reference{};
  std::vector<LogEvent> events{};  // in the order they are to be stored
  std::map<std::string, std::uint64_t> skipped{}, reference_skipped{};
  std::optional<std::string> damage{};
};

struct ImuLogSettings {
  double accel_lsb = 0, gyro_lsb = 0;  // the frames' resolution
  estimator::ImuAxes declared_axes{};
  std::string imu_axes{};  // as declared, recorded with the link
  double gap_threshold_s = kDefaultGapThresholdS;
  ImportProgressCallback progress{};
  std::uint64_t file_size = 0;  // for progress
  ProblemCallback on_problem{};
};

// The settings from an import's options, checked before anything is read: throws std::invalid_argument for
// resolutions that are not positive and finite, a gap threshold that is not, or IMU axes that do not parse. `progress`
// and the file's size (for it) and `on_problem` are taken along.
ImuLogSettings imu_log_settings(double accel_lsb, double gyro_lsb, const std::string& imu_axes, double gap_threshold_s,
                                const ImportProgressCallback& progress, const std::filesystem::path& file,
                                const ProblemCallback& on_problem);

// What an on-board log's import made; what it skipped, clipped or found damaged went to `on_problem`.
struct ImuLogImportResult {
  std::int64_t session = 0;
  std::string imu_source;
  std::uint64_t samples = 0;  // IMU samples imported
  std::uint64_t reference_rows = 0;
  std::uint64_t first_us = 0, last_us = 0;  // the first and last sample's log times
  Gaps gaps;                                // holes in the IMU's data
  estimator::AxesResolution axes;
};

// Records `log` as a new session (ImportSession): one link `imu0` of imubridge frames (the rows, encoded at the
// settings' resolution), the reference, the events, then the skipped and clipped records and the damage as problems,
// the gaps and an axes mismatch as events.
// Both receive clocks are the log's time in ns, the device clock the log's µs. Fills `result` (its own fields only).
void record_imu_log(store::Store& store, ImuLog log, const ImuLogSettings& settings, ImuLogImportResult& result);

}  // namespace imubridge::importers
