#pragma once
// The estimator's input: plain IMU time series in SI units, independent of the protocol and store layers.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

namespace imubridge::estimator {

struct TimeWindow {
  double start = 0.0;  // s, session time
  double end = 0.0;    // s, exclusive

  friend bool operator==(const TimeWindow&, const TimeWindow&) = default;
};

// One IMU measurement: what the live estimator consumes.
struct ImuSample {
  double t = 0.0;                                   // s
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();   // angular rate, rad/s, IMU axes
  Eigen::Vector3d accel = Eigen::Vector3d::Zero();  // specific force, m/s^2, IMU axes
};

// Ground truth from a motion-capture system or a simulator, sample for sample with the IMU series.
struct ReferenceSeries {
  std::vector<Eigen::Vector3d> velocity_ned;  // mass-centre velocity, m/s, world NED
  std::vector<Eigen::Quaterniond> attitude;   // body -> NED rotation (v_ned = q * v_body)
};

struct ImuSeries {
  std::vector<double> t;                     // s, strictly increasing
  std::vector<Eigen::Vector3d> gyro;         // rad/s, IMU axes
  std::vector<Eigen::Vector3d> accel;        // m/s^2, IMU axes
  std::optional<ReferenceSeries> reference;  // same length as t when present
  // Where the autopilot's land detector says the vehicle stood on the ground, on t's clock, in time order: the
  // estimator fuses rest there (DragVelocityEstimator::set_landed), as the live pipeline does. Empty without one.
  std::vector<TimeWindow> landed;

  std::size_t size() const { return t.size(); }
  ImuSample sample(std::size_t i) const { return {t[i], gyro[i], accel[i]}; }
};

// Whether the land detector says landed at each of a series' times in turn (non-decreasing): one pass over `landed`.
class LandedCursor {
 public:
  explicit LandedCursor(const std::vector<TimeWindow>& landed) : landed_(landed) {}
  bool at(double t) {
    while (next_ < landed_.size() && !(t < landed_[next_].end)) ++next_;
    return next_ < landed_.size() && landed_[next_].start <= t;
  }

 private:
  const std::vector<TimeWindow>& landed_;
  std::size_t next_ = 0;
};

// Why `series` cannot be used (mismatched lengths, non-finite values, times not strictly increasing, attitude not
// a unit quaternion), or nullopt when it can. The batch functions throw std::invalid_argument with this message.
std::optional<std::string> validate(const ImuSeries& series);
void require_valid(const ImuSeries& series);

// What names one flight wherever its samples are (a store, a synced copy, a replay): a hash of its first samples' times
// and readings as stored (replay::SessionSeries::flight hashes them before any cut or rotation), "imu:" and 16 hex
// digits. PARAMS.json records it beside the conditions fitted on that flight
// (params.hpp), so that no other flight is estimated with them.
std::string flight_identity(const ImuSeries& series);

}  // namespace imubridge::estimator
