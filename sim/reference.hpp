#pragma once
// The reference trajectory as a user's receiver gives it (docs/simulator.md, "Reference"): a GNSS position and
// velocity describe the vehicle some time before they are stamped, come at 5-10 Hz and are rounded; the attitude is
// the autopilot's, current. The defaults give the truth at every IMU sample.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <deque>
#include <optional>

#include "sim/flight.hpp"

namespace imubridge::sim {

struct ReferenceConfig {
  double delay_s = 0.0;           // position and velocity describe the vehicle this long before their stamp
  double rate_hz = 0.0;           // poses per second; 0: one at every IMU sample
  double velocity_quantum = 0.0;  // m/s, each velocity component rounded to a multiple of it; 0: not rounded

  bool is_truth() const { return delay_s == 0.0 && rate_hz == 0.0 && velocity_quantum == 0.0; }
};

struct ReferencePose {
  double t = 0.0;  // s, the stamp: the IMU's clock
  Eigen::Vector3d position_ned = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity_ned = Eigen::Vector3d::Zero();
  Eigen::Quaterniond attitude = Eigen::Quaterniond::Identity();  // body -> NED, at the stamp
};

class ReferenceReceiver {
 public:
  explicit ReferenceReceiver(const ReferenceConfig& config);
  // Every truth sample, in time order; the pose stamped at its time when the receiver gives one then (none before
  // the first delayed state exists, nor between two poses of a slower rate).
  std::optional<ReferencePose> next(const TrueState& truth);

 private:
  struct Past {
    double t;
    Eigen::Vector3d position, velocity;
  };
  ReferenceConfig config_;
  std::deque<Past> past_;  // the last delay_s of truth, and one sample before it
  std::optional<double> first_stamp_;
  std::uint64_t stamps_ = 0;  // poses given on the rate's grid
};

}  // namespace imubridge::sim
