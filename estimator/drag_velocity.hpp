#pragma once
// Drag-velocity estimator, the paper's section VIII done properly: the body-frame horizontal velocity from the drag
// that the lever-arm-compensated horizontal accelerometers measure, fused in a 6-state extended Kalman filter with
// the gyro-propagated gravity direction. State and noise design: docs/estimator.md.
#include <Eigen/Core>
#include <array>
#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

#include "estimator/constants.hpp"
#include "estimator/differentiator.hpp"
#include "estimator/full_model.hpp"
#include "estimator/imu_series.hpp"
#include "estimator/lever_arm_compensation.hpp"
#include "estimator/params.hpp"

namespace imubridge::estimator {

struct DragVelocityConfig {
  int differentiator_window = 5;        // samples in the causal omega_dot fit (odd); the output lags by (N-1)/2
  double max_gap = 0.1;                 // s; a longer silence restarts the differentiator
  double accel_noise = 0.1;             // m/s^2, std of one compensated horizontal specific-force sample
  double accel_process_noise = 0.5;     // m/s^2/sqrt(Hz): unmodelled horizontal acceleration (gusts, model error)
  double gyro_noise = 1e-3;             // rad/s/sqrt(Hz), gyro white-noise density
  double gyro_bias_walk = 1e-4;         // rad/s^2/sqrt(Hz), gyro bias random walk
  double initial_velocity_std = 1.0;    // m/s
  double initial_tilt_std = 0.1;        // of the body x, y components of the gravity direction (~rad)
  double initial_gyro_bias_std = 0.02;  // rad/s
  // Never inventing a speed (docs/estimator.md, "Honest variance, and rest"). A constant offset of the horizontal
  // specific force (the accelerometer's zero-g offset on a flight the calibration was not fitted on) reads through the
  // drag law's inverse as a velocity offset (offset / k for a linear law) that no run of white noise averages away;
  // its std. 0 on the flight the model was fitted on, where the fit placed the offset; config_for sets
  // kTransferredOffsetStd on any other.
  double accel_offset_std = 0.0;  // m/s^2
  // The drag gives the velocity through the air; the vehicle's over the ground differs by the wind, which no IMU sees
  // on a steady heading. On the flight the model was fitted on, its wind went into the fit; on any other the two
  // flights' winds differ by an unknown amount, per horizontal axis, with this std (config_for: kTransferredWindStd).
  double wind_std = 0.0;  // m/s
  // What is known of a multirotor's speed before any measurement: within a brisk 5 m/s (plausibility.hpp's
  // kBriskSpeed). The output is the filter's velocity weighed against it: where the drag's slope is too weak for the
  // offset above to be small, the estimate relaxes towards rest and its variance says how little is known.
  double rest_speed_std = 5.0;  // m/s
  // How still a vehicle stands that the autopilot's land detector calls landed (set_landed): on its legs, motors
  // idling or off, it moves by centimetres per second at most.
  double landed_speed_std = 0.05;  // m/s
  // Beyond any MEMS full scale: a sample outside is corrupt, and one would wreck the filter's state.
  double max_specific_force = 16.0 * kGravity;  // m/s^2, per axis
  double max_rate = 35.0;                       // rad/s (2000 deg/s), per axis
};

// The filter's settings for identified parameters: the measurement noise becomes the identification's horizontal
// residual RMS (validation window, else fit window) when that is larger than `base`'s. A vibrating airframe's
// accelerometers read many times their datasheet noise, and a filter that trusts each drag reading as if it were
// clean swings its velocity with every vibration. Never lower than `base`: a short calm identification window must
// not make the filter overconfident. Parameters without an identification keep `base`. A process noise the
// identification fitted (the filter error method) replaces base's.
DragVelocityConfig config_for(const ModelParams& params, DragVelocityConfig base = {});
// What a calibration carried to another flight does not know of that flight's accelerometer offset, m/s^2, unless it
// measured it on its validating flights (Identification::transfer_offset_std): the upper end of a consumer MEMS
// accelerometer's zero-g offset (0.02-0.06 g). The upper end, because a variance that claims more than is known
// flies worse than "not moving", and a strapped-on IMU moved by a degree adds 0.17 m/s^2 of its own.
inline constexpr double kTransferredOffsetStd = 0.06 * kGravity;
// The difference between two flights' winds along one body axis, m/s, when nothing measured it: each flight's a light
// breeze (Beaufort 2, up to 3.3 m/s at 10 m), 3 m/s std, independent from one flight to the next, so sqrt(2) * 3.
inline const double kTransferredWindStd = std::sqrt(2.0) * 3.0;

struct DragVelocityEstimate {
  double t = 0.0;                                       // s: the sample this describes, delay_samples() back
  Eigen::Vector2d f = Eigen::Vector2d::Zero();          // compensated horizontal specific force (the drag), m/s^2
  Eigen::Vector2d f_var = Eigen::Vector2d::Zero();      // its variance, (m/s^2)^2
  Eigen::Vector2d v_raw = Eigen::Vector2d::Zero();      // the drag law inverted, sample by sample, m/s
  Eigen::Vector2d v_raw_var = Eigen::Vector2d::Zero();  // (m/s)^2
  // Filtered body-frame horizontal velocity, m/s, weighed against rest (accel_offset_std, rest_speed_std), and its
  // variance, which counts the offset's share: the error it reports is the error it has.
  Eigen::Vector2d v = Eigen::Vector2d::Zero();
  Eigen::Vector2d v_var = Eigen::Vector2d::Zero();      // (m/s)^2
  Eigen::Vector2d gyro_bias = Eigen::Vector2d::Zero();  // estimated body x, y gyro bias, rad/s
  // The one-step prediction, per axis just before that axis's measurement is fused (x first, then y): the body-axis
  // air velocity the drag law saw (m/s), and the innovation f - drag(it) (m/s^2). The filter error method
  // (docs/identification.md) fits the model by these; an axis without drag predicts no force.
  Eigen::Vector2d prior_air_velocity = Eigen::Vector2d::Zero();
  Eigen::Vector2d innovation = Eigen::Vector2d::Zero();
  // The innovation's variance as the filter predicts it, (m/s^2)^2: the law's slope squared times the prior velocity's
  // variance plus the measurement noise (the noise alone on an axis without drag). With the innovation it gives the
  // filter's likelihood of the measurements (filter_log_likelihood), by which an IMU-only model is judged.
  Eigen::Vector2d innovation_var = Eigen::Vector2d::Zero();
};

struct DragVelocityCounters {
  std::uint64_t samples_in = 0;
  std::uint64_t estimates_out = 0;
  std::uint64_t rejected_non_finite = 0;
  std::uint64_t rejected_out_of_range = 0;  // beyond max_specific_force or max_rate
  std::uint64_t rejected_time = 0;          // timestamp not after the previous accepted sample's
  std::uint64_t gaps = 0;                   // restarts after more than max_gap without samples
  std::uint64_t clock_restarts = 0;         // the device's clock started again (restart_clock)
  // Estimates made on the ground (set_landed): a zero-velocity update instead of the drag.
  std::uint64_t landed = 0;
  // The filter lost itself (a state or variance not finite, or a velocity variance collapsed to nothing: a crash's
  // tumble and 12-g spikes do it) and started again from level and rest, knowing nothing of the velocity.
  std::uint64_t resets = 0;
  // Accepted samples not estimated because the time_offset aligner had no history |time_offset| back yet: the first
  // |time_offset| seconds of the flight and after each gap (always 0 without a time offset).
  std::uint64_t aligning = 0;
};

class DragVelocityEstimator {
 public:
  // Throws std::invalid_argument for invalid params or a bad config. An axis without drag (k = mu = 0) has nothing to
  // invert: its force is still compensated. With drag on the other axis it reads rest, with rest_speed_std's variance
  // (the limit of weighing against rest as the drag vanishes); with drag on neither (nothing identified yet) NaN.
  DragVelocityEstimator(const FullModelParams& params, const DragVelocityConfig& config);

  // O(1) work (amortised, with a time offset) and no allocation. Returns the estimate for the sample delay_samples()
  // back once the differentiator window is full. A rejected sample is counted and leaves the estimator exactly as
  // it was. With a time offset, the sample at t is estimated with the gyro of t - time_offset (interpolated) and
  // keeps its t; samples before the aligner holds |time_offset| of history are counted as `aligning`.
  std::optional<DragVelocityEstimate> update(const ImuSample& sample);
  // The device restarted: its clock counts from an earlier value now, `elapsed` seconds (by the receiver's clock)
  // after its last sample. The differentiator and the aligner start again as after a gap; the state is kept, its
  // uncertainty grown by `elapsed` of process noise, so a short restart costs the velocity nothing.
  void restart_clock(double elapsed);

  // The autopilot's land detector (docs/estimator.md, "On the ground"): while landed, the legs hold the vehicle, not
  // the air, so the filter fuses rest (landed_speed_std) in place of the drag law and predicts with the measured
  // horizontal force, which levels its tilt on the accelerometer and lets it learn the gyro bias: no speed is read
  // into the stance's tilt or the accelerometer's offset, and the flight starts from rest. Takes effect from the
  // next update. Without a land detector nothing calls it, and the filter reads the drag from its first sample.
  void set_landed(bool landed) { landed_ = landed; }
  bool landed() const { return landed_; }

  const DragVelocityCounters& counters() const { return counters_; }
  int delay_samples() const { return differentiator_.delay_samples(); }
  bool has_drag(int axis) const { return params_.drag_linear[axis] + params_.drag_quadratic[axis] > 0.0; }

 private:
  using Vector6d = Eigen::Matrix<double, 6, 1>;
  using Matrix6d = Eigen::Matrix<double, 6, 6>;

  struct Stamped {
    double t = 0.0;
    Eigen::Vector3d value = Eigen::Vector3d::Zero();
  };

  // The wind's projection into the body, linearised once at the prediction for both axes' updates.
  struct WindLinearisation {
    Eigen::Vector2d wind = Eigen::Vector2d::Zero();
    Eigen::Matrix2d jacobian = Eigen::Matrix2d::Zero();        // of `wind` by (gamma_x, gamma_y)
    Eigen::Vector2d predicted_tilt = Eigen::Vector2d::Zero();  // the tilt it was linearised at
  };

  // Counts a sample that is not finite, out of range or not after the last as rejected (false); restarts the window
  // after a gap.
  bool accept(const ImuSample& sample);
  // Predicts the state to the window centre's time, or across a gap grows its uncertainty alone. `force` is the
  // centre's compensated horizontal specific force, which drives the prediction on the ground.
  void propagate_to(const ImuSample& centre, const Eigen::Vector2d& force);
  // With wind the drag inverts to the air velocity; the state and the output stay the ground velocity. Zero without.
  WindLinearisation linearise_wind() const;
  // One horizontal axis's prediction, drag measurement (or, landed, rest) and output into `out` (whose f is set).
  void fuse_axis(int axis, const WindLinearisation& wind, DragVelocityEstimate& out);
  // Landed: the zero-velocity update on `axis` and its output (estimator/zero_velocity_update.cpp).
  void fuse_zero_velocity(int axis, DragVelocityEstimate& out);
  // The output velocity and variance: the filter's, with the offset's share, weighed against rest.
  void weigh_against_rest(int axis, DragVelocityEstimate& out) const;
  // Pairs the accelerometer with the gyro of time_offset earlier: delays the gyro (time_offset > 0) or the
  // accelerometer (< 0) through a ring. False while the ring does not reach back far enough.
  bool align(ImuSample& sample);
  // The covariance of a filter that starts level and unbiased (config's initial stds), its velocity this unsure.
  Matrix6d initial_covariance(double velocity_std) const;
  // Whether the filter has lost itself (DragVelocityCounters::resets).
  bool diverged() const;
  // Starts the state again from level and rest, the velocity as unknown as the prior, and writes that into `out`.
  void reset_after_divergence(DragVelocityEstimate& out);
  // Empties the differentiator's window and the aligner: no derivative or interpolation across a break.
  void restart_window();
  // `held_force`: on the ground, the measured horizontal specific force in place of the drag law's.
  void predict(double dt, const Eigen::Vector3d& w_measured, const Eigen::Vector2d* held_force);
  // The drag law inverted, fused as a velocity measurement with the accelerometer's noise through the law's slope.
  void fuse_velocity(int axis, double v_measured);
  // The scalar Kalman update of the velocity on `axis` by a measurement of variance `r`.
  void update_velocity(int axis, double v_measured, double r);
  // |d drag / d v| on `axis` for fusing there (its noise is the accelerometer's divided by it).
  double fusion_slope(int axis, double predicted) const;
  // Turns the heading by `angle` (rad).
  void turn_heading(double angle);
  // The wind in body x, y at the state's tilt and heading, and its Jacobian by (gamma_x, gamma_y).
  Eigen::Vector2d wind_in_body(Eigen::Matrix2d* jacobian) const;
  // The drag measurement of a windy model: `air` is the inverted drag, h(x) = v - R^T w, with `wind` that axis's
  // R^T w at the current state and `jacobian` its derivative by (gamma_x, gamma_y).
  void fuse_air_velocity(int axis, double air, double wind, const Eigen::Vector2d& jacobian);

  FullModelParams params_;
  DragVelocityConfig config_;
  LeverArmCompensator compensator_;
  CausalDifferentiator differentiator_;
  // The last samples, so the accelerometer and gyro are read at the differentiator window's centre: the time its
  // omega_dot belongs to.
  std::array<ImuSample, CausalDifferentiator::kMaxWindow> history_{};
  int head_ = 0;
  std::optional<double> last_input_t_;

  // The time_offset aligner: the delayed stream's last samples, oldest at ring_sequence_ - ring_size_ (in sample
  // numbers since the last reset). Allocated once, in the constructor, and only with a time offset.
  static constexpr std::size_t kAlignerCapacity = 1024;  // 0.25 s at 4 kHz
  std::vector<Stamped> ring_;
  std::uint64_t ring_sequence_ = 0;  // samples pushed since the last reset
  std::uint64_t ring_cursor_ = 0;    // the newest sample at or before the last query time
  std::size_t ring_size_ = 0;

  // Wind: the heading (yaw) of the body in the identification's world frame, integrated from wind_heading, as its
  // cosine and sine.
  bool windy_ = false;
  double heading_cos_ = 1.0, heading_sin_ = 0.0;

  bool landed_ = false;  // set_landed

  // x = (v_x, v_y, gamma_x, gamma_y, b_x, b_y): body velocity, body x, y of the gravity direction, gyro bias.
  Vector6d x_ = Vector6d::Zero();
  Matrix6d p_ = Matrix6d::Zero();
  Vector6d process_density_ = Vector6d::Zero();  // continuous-time process noise, per unit time
  std::optional<double> filter_t_;

  DragVelocityCounters counters_;
};

}  // namespace imubridge::estimator
