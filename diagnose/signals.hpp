#pragma once
// The per-sample signals `imubridge diagnose` works from, prepared once from an ImuSeries: nothing here depends on a
// model parameter. The model (model.hpp) starts from them and lets effects adjust its own copies; the residual
// analysis correlates the residual with the named candidates (candidate_signals).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cstddef>
#include <optional>
#include <span>
#include <vector>

#include "diagnose/residual_analysis.hpp"
#include "estimator/imu_series.hpp"

namespace imubridge::diagnose {

// The body frame as the reference trajectory sees it, sample for sample.
struct ReferenceSignals {
  std::vector<Eigen::Vector3d> velocity_body;  // mass-centre ground velocity, body axes, m/s
  std::vector<Eigen::Quaterniond> attitude;    // body -> NED
};

struct Signals {
  std::vector<double> t;                      // s
  double rate_hz = 0.0;                       // sample rate: 1 / median step (sample_rate_hz)
  std::vector<Eigen::Vector3d> gyro;          // rad/s, IMU axes
  std::vector<Eigen::Vector3d> gyro_rate;     // rad/s^2, IMU axes (estimator::smoothed_derivative)
  std::vector<Eigen::Vector3d> accel;         // measured specific force, m/s^2, IMU axes
  std::optional<ReferenceSignals> reference;  // when the series has a reference trajectory
  // The rotation taking the mean measured specific force to -z: an IMU -> body rotation up to yaw, for a sensor
  // mounted in any orientation (the full model starts its mounting here). Rotation vector, rad.
  Eigen::Vector3d level_mounting = Eigen::Vector3d::Zero();
  // Measured thrust specific force: minus the specific force along the mean thrust axis (level_mounting), m/s^2.
  std::vector<double> thrust;
  // Tilt by eq. (11) in the levelled frame: roll and pitch, each the integral of its body rate from zero, rad.
  std::vector<Eigen::Vector2d> tilt;
  // The two IMU axes closest to the levelled body's x and y (0, 1 or 2): where horizontal sensor errors show.
  std::array<int, 2> horizontal_sensor_axes{0, 1};

  std::size_t size() const { return t.size(); }
};

// The rotation matrix of a rotation vector (axis times angle, rad).
Eigen::Matrix3d rotation_matrix(const Eigen::Vector3d& rotation_vector);
// R_bs of the levelled body frame: rotation_matrix(signals.level_mounting).
inline Eigen::Matrix3d level_rotation(const Signals& signals) { return rotation_matrix(signals.level_mounting); }

// The filter error method (velocity `filter`) identifies in the manoeuvres' band, below about 5 Hz: its filter
// runs on block means at about five times that. The blocks average the vibration out, so what the filter is told is
// noise is close to white, and its one-step prediction spans 40 ms, so a filter that merely follows the measurement
// predicts no better than the model (docs/identification.md, "From the IMU alone").
inline constexpr double kIdentificationRateHz = 25.0;
// Samples per block at `rate_hz`: rate / kIdentificationRateHz, rounded, at least 1.
std::size_t identification_block(double rate_hz);
// The means of samples [j * block, (j + 1) * block) for j < blocks (time, gyro, specific force), in IMU axes.
std::vector<estimator::ImuSample> block_means(std::span<const double> t, std::span<const Eigen::Vector3d> gyro,
                                              std::span<const Eigen::Vector3d> accel, std::size_t block,
                                              std::size_t blocks);

// Half window of the angular acceleration's cubic fit (see estimator::smoothed_derivative).
inline constexpr double kDerivativeHalfWindowS = 0.0315;

// Throws std::invalid_argument for an invalid series (estimator::require_valid) or one with fewer than 2 samples.
Signals prepare_signals(const estimator::ImuSeries& series, double derivative_half_window = kDerivativeHalfWindowS);

// The model's velocity (body axes) at each sample, for the candidates: it comes from the reference or from
// integrating the gyro and depends on the model, so the caller passes it.
// Candidates for the cross-correlation over samples [first, first + count): gyro.{x,y,z}, gyro_rate.{x,y,z},
// gyro.{x,y,z}^2, accel.{x,y,z}, velocity.{x,y}, tilt.{x,y} (roll, pitch), thrust.
std::vector<NamedSignal> candidate_signals(const Signals& signals, const std::vector<Eigen::Vector3d>& velocity_body,
                                           std::size_t first, std::size_t count);

}  // namespace imubridge::diagnose
