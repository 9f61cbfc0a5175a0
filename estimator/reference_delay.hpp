#pragma once
// How late a session's reference velocity is behind its IMU, from the data alone (docs/identification.md,
// "Reference delay"). A GNSS receiver's velocity describes the vehicle 0.1-0.3 s before it is stamped, at 5-10 Hz;
// a model fitted or scored against it unshifted is judged against the past.
//
// Model-free: the reference's velocity differenced over each of its own intervals (at least kDelayBoxSeconds long)
// is the mean acceleration over that interval, exactly; the IMU's specific force turned into NED with the reference
// attitude, plus gravity, averaged over the same interval moved by a candidate lag, is the same quantity measured by
// the IMU. Both sides are the same box filter, so any reference rate (5-200 Hz) and IMU rate compare without
// resampling. The lag whose horizontal accelerations correlate best, refined between candidates by a parabola, is
// the delay; a weak, flat, ambiguous or edge peak is reported as such and not used.
#include <Eigen/Core>
#include <cstddef>
#include <optional>
#include <span>
#include <string>

#include "estimator/imu_series.hpp"

namespace imubridge::estimator {

// Candidate lags: within +-kMaxReferenceDelay, every kDelayLagStep. A receiver's latency is 0.05-0.3 s; a delay
// beyond half a second is a clock problem, not a latency, and is left to --reference-delay.
inline constexpr double kMaxReferenceDelay = 0.5;  // s
inline constexpr double kDelayLagStep = 0.005;     // s; the parabola refines between candidates
// The shortest interval a reference velocity is differenced over: a 50-200 Hz reference differenced sample by sample
// is mostly its own noise; a 5-10 Hz one is differenced over its own interval.
inline constexpr double kDelayBoxSeconds = 0.2;
// Below this correlation at the best lag the two accelerations are not the same signal (a hover, a reference too
// noisy or in another frame): nothing is shifted.
inline constexpr double kMinDelayCorrelation = 0.5;
// Below this horizontal acceleration (RMS about its mean, m/s^2, the reference's) the vehicle hardly manoeuvres:
// half a degree of attitude error alone is 0.09 m/s^2, so a peak would say nothing about time.
inline constexpr double kMinDelayAcceleration = 0.15;
// Another peak of the correlation within this of the best one, with a dip of more than this between them: periodic
// manoeuvres, the lag is ambiguous.
inline constexpr double kDelayAmbiguity = 0.05;
// Fewer boxes than this (a few seconds of data) is too little to estimate from.
inline constexpr std::size_t kMinDelayBoxes = 20;

struct ReferenceDelay {
  double delay_s = 0.0;           // the reference lags the IMU by this (negative: it leads)
  double correlation = 0.0;       // at the best lag
  double curvature = 0.0;         // -d^2(correlation)/d(lag)^2 at the best lag, 1/s^2: how sharp the peak is
  double acceleration_rms = 0.0;  // the reference's horizontal acceleration about its mean, m/s^2
  std::size_t boxes = 0;          // reference intervals compared
  std::optional<std::string> unusable;  // why the estimate is not to be used, or nullopt
  bool usable() const { return !unusable; }
};

// "0.21 s (correlation 0.87)", or "cannot be estimated (REASON)".
std::string describe(const ReferenceDelay& delay);

// `series`: IMU samples in body axes with the reference attitude (body -> NED) at each sample; its reference velocity
// is not read. `reference_t` and `reference_velocity_ned`: the reference's own samples (strictly increasing times on
// the series' clock). Throws std::invalid_argument without a reference attitude or for mismatched lengths.
ReferenceDelay estimate_reference_delay(const ImuSeries& series, std::span<const double> reference_t,
                                        std::span<const Eigen::Vector3d> reference_velocity_ned);

}  // namespace imubridge::estimator
