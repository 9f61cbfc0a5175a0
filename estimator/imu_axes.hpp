#pragma once
// How an IMU's axes sit in the vehicle's FRD body frame (x forward, y right, z down), declared or detected from
// gravity, and how a reference attitude's frame relates to the IMU's axes. Everything downstream (model,
// identification, estimator, diagnose) takes samples in body axes, up to the small mounting rotation it fits;
// replay::read_session_series and pipeline::EstimationStage apply what is resolved here. docs/estimator.md,
// "IMU axes".
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "estimator/imu_series.hpp"

namespace imubridge::estimator {

struct ImuAxes {
  Eigen::Matrix3d imu_to_body = Eigen::Matrix3d::Identity();  // R_bs: v_body = R_bs * v_imu
  std::string name = "auto";  // "frd", "flu", "x-up", ..., "auto", or "R:..." / "q:..." as given
  bool automatic = true;      // "auto": imu_to_body is to be resolved from the data (resolve_axes)
};

ImuAxes frd_axes();
ImuAxes auto_axes();
// frd | flu | x-up | x-down | y-up | y-down | auto | R:r00,r01,...,r22 (row-major R_bs, orthonormal to 1e-6,
// det +1) | q:w,x,y,z (IMU -> body quaternion, normalised; rejected further than 1e-3 from unit length). Throws
// std::invalid_argument with a one-line message listing the valid spellings.
ImuAxes parse_imu_axes(std::string_view text);
// The name for named conventions and auto, else "R:" with the matrix row-major (round-trips parse_imu_axes).
std::string to_string(const ImuAxes& axes);
// True when imu_to_body is exactly the identity: rotating would change nothing, so callers skip the multiply.
bool is_identity(const ImuAxes& axes);

// ---- gravity detection ----

// At rest before take-off. The thresholds are physical, not fitted to a data set:
// - a MEMS gyro at rest reads its noise (~0.005-0.01 deg/s/sqrt(Hz), i.e. < 0.003 rad/s RMS over 200 Hz) plus an
//   uncalibrated bias of up to ~1 deg/s (0.02 rad/s); a hovering vehicle's attitude loop moves it by 0.1-0.5 rad/s.
inline constexpr double kRestMaxGyroRms = 0.05;  // rad/s
// - at rest the specific force is g whatever the orientation; scale-factor and bias errors of a consumer MEMS part
//   stay within ~3 %, a vehicle taking off or landing leaves 5 % within a fraction of a second.
inline constexpr double kRestNormTolerance = 0.05;  // relative to g
// - accelerometer noise (~150-300 ug/sqrt(Hz), < 0.05 m/s^2 RMS) and idling motors' vibration stay well under this;
//   a hand-held or moving vehicle exceeds it.
inline constexpr double kRestMaxAccelSpread = 0.5;  // m/s^2, RMS of the vector about its mean
// - long enough to average the noise down to well under a degree, short enough for a brief wait before take-off.
inline constexpr double kRestWindowSeconds = 0.5;
// - where to look for the rest segment: a session starts on the ground within this, or it is taken in flight.
inline constexpr double kRestSearchSeconds = 30.0;
// In flight the mean specific force over the series is the mean thrust, along body -z: a few seconds average out
// manoeuvres (tilts of 10-30 deg average to a few deg over a flight that returns). Live detection decides after this.
inline constexpr double kFlightDecisionSeconds = 5.0;
// Below this the mean specific force says nothing about up (free fall, a thrown or tumbling sensor, no data).
inline constexpr double kMinMeanSpecificForce = 0.5 * 9.80665;  // m/s^2
// Farther than this from the nearest axis, the snapped convention is noticeably tilted: the fitted mounting absorbs
// it, but the user should know.
inline constexpr double kTiltNoteDegrees = 10.0;
// A declared convention whose "up" is farther than this from the detected one disagrees with the data.
inline constexpr double kMismatchDegrees = 45.0;

enum class UpMethod { at_rest, in_flight };
std::string_view name(UpMethod method);  // "at rest", "in flight"

struct AxesDetection {
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();  // unit, IMU axes: where the specific force points (against g)
  UpMethod method = UpMethod::at_rest;
  double t_start = 0.0, t_end = 0.0;  // s, the samples' own times
  std::size_t samples = 0;
};
// "gravity +z at rest, 0-2.1 s" (the nearest signed axis, and its tilt when above kTiltNoteDegrees).
std::string describe(const AxesDetection& detection);

// Up in IMU axes: from the first at-rest segment (>= kRestWindowSeconds, every kRestWindowSeconds window within it
// passing all three rest tests, starting within kRestSearchSeconds), else from the mean specific force over all the
// samples. Nothing when the series is empty or its mean specific force is below kMinMeanSpecificForce.
std::optional<AxesDetection> detect_up(std::span<const double> t, std::span<const Eigen::Vector3d> accel,
                                       std::span<const Eigen::Vector3d> gyro);
std::optional<AxesDetection> detect_up(const ImuSeries& series);

// Live detection over the first samples of a link: decided at rest as soon as the last kRestWindowSeconds are at
// rest, else in flight once kFlightDecisionSeconds of samples are in (the mean over them; nothing detected when that
// is below kMinMeanSpecificForce). A live link cannot wait kRestSearchSeconds, so the rest search ends there too.
// Deterministic: the same samples decide at the same sample with the same result.
class UpDetector {
 public:
  // True once decided (and on every later call, which then ignores the sample).
  bool add(double t, const Eigen::Vector3d& accel, const Eigen::Vector3d& gyro);
  bool decided() const { return decided_; }
  const std::optional<AxesDetection>& result() const { return result_; }

 private:
  std::vector<double> t_;
  std::vector<Eigen::Vector3d> accel_, gyro_;
  bool decided_ = false;
  std::optional<AxesDetection> result_;
};

// ---- from up to axes ----

struct UpSnap {
  ImuAxes axes;             // the convention for `up`
  Eigen::Vector3d axis;     // the signed IMU axis nearest `up`
  double tilt_rad = 0.0;    // angle between `up` and `axis`
};
// What auto resolves to: body z (down) = minus the signed IMU axis nearest `up`; body x = IMU +x unless x is that
// vertical axis, then IMU +z; body y = z x x. frd for z down, flu for z up, x-up for x up.
UpSnap from_up(const Eigen::Vector3d& up);

struct AxesResolution {
  ImuAxes declared;                  // as given (may be auto)
  ImuAxes axes;                      // what is applied: never automatic
  std::optional<AxesDetection> detection;
  std::string description;           // "IMU axes flu (auto: gravity +z at rest, 0-2.1 s)"
  std::optional<std::string> mismatch;  // one line when a declared convention disagrees with the data
  std::optional<std::string> note;      // one line: auto without a detection, or a large tilt
};
// auto: from_up(detection), or frd with a note when nothing was detected. Declared: kept (the user's word), with
// a mismatch line naming the declared axes, the detected up axis and what to declare instead when R_bs * up is more
// than kMismatchDegrees from body up (0, 0, -1).
AxesResolution resolve_axes(const ImuAxes& declared, const std::optional<AxesDetection>& detection);

// ---- the reference attitude's frame ----

// Motion capture gives the attitude of whatever it tracked: EuRoC's ground truth is the IMU's (sensor -> world), a
// simulator's or an autopilot's may be the body's. Rather than guess, compare the reference's rotation increments
// (Log(q_a^-1 q_b), reference frame) with the gyro's over the same spans (IMU axes), span by span.
inline constexpr double kAlignSpanSeconds = 0.25;  // short enough for a small-angle, bias-free increment
inline constexpr std::size_t kAlignMinSpans = 8;
// A span turning less than this is dominated by gyro noise and bias and by reference jitter: left out.
inline constexpr double kAlignMinSpanAngle = 0.02;  // rad
// Second singular value over the first below this: the rotations are (nearly) about one axis, so the rotation about
// it is undetermined and no frame other than the two hypotheses is estimated.
inline constexpr double kAlignMinSingularRatio = 0.05;
// The estimate is "neither the IMU's frame nor the body's" when farther than this from both; nearer, the nearer of
// the two is the candidate (the rest is the mounting the model fits).
inline constexpr double kAlignSnapDegrees = 20.0;
// The two hypotheses are told apart by how well each explains the increments: the wrong frame's RMS misfit must be at
// least this many times the right one's. A flight turning about one axis only still tells the frames apart when they
// differ about another axis (an IMU strapped on upside down, yawing); when they differ only about the axis it turns
// about, or its rotations are within the noise, both misfit alike and the check says it cannot tell. A worse misfit
// below kAlignMinSpanAngle is within a span's noise: cannot tell either.
inline constexpr double kAlignMinContrast = 2.0;

// One span of a series: the rotation the reference turns through, Log(q_a^-1 q_b) (the reference's frame), and the
// one the gyro integrates (trapezoidal, the gyro's axes), rad, over samples [a, b], b the first at least
// `seconds` after a.
struct SpanRotation {
  Eigen::Vector3d reference = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();
  double seconds = 0.0;
};
// Consecutive spans of at least `span_seconds` over samples [first, end); a span holding a gap in the samples longer
// than that is left out (the gyro did not see that rotation), and so is a last span too short.
std::vector<SpanRotation> span_rotations(std::span<const double> t, std::span<const Eigen::Vector3d> gyro,
                                         std::span<const Eigen::Quaterniond> attitude, std::size_t first,
                                         std::size_t end, double span_seconds);

// cannot_tell: too few turning spans, or the two hypotheses explain them about equally; the IMU's frame is applied
// and a warning says so.
enum class ReferenceFrame { imu, body, estimated, cannot_tell };
std::string_view name(ReferenceFrame frame);

struct ReferenceAlignment {
  Eigen::Matrix3d ref_from_imu = Eigen::Matrix3d::Identity();  // what to apply: v_ref = R * v_imu
  ReferenceFrame frame = ReferenceFrame::cannot_tell;
  Eigen::Matrix3d estimate = Eigen::Matrix3d::Identity();  // Wahba's solution (identity when not estimated)
  Eigen::Vector3d singular_values = Eigen::Vector3d::Zero();
  std::size_t spans = 0;          // spans used
  double rms_misfit_rad = 0.0;    // RMS of |r_ref - R r_imu| over the spans, for the estimate
  double misfit_as_imu_rad = 0.0;   // the same for the IMU's frame (R = I)
  double misfit_as_body_rad = 0.0;  // and for the body's (R = R_bs)
  bool estimate_determined = false;  // enough spans, rotations about more than one axis: `estimate` is meaningful
  double snap_angle_rad = 0.0;    // angle between the estimate and what is applied
};
std::string describe(const ReferenceAlignment& alignment);

// `series` in IMU axes with a reference (body -> world in the reference's own sense); `imu_to_body` the axes the IMU
// is declared or detected in. Throws std::invalid_argument without a reference.
ReferenceAlignment align_reference_frame(const ImuSeries& series, const Eigen::Matrix3d& imu_to_body);

// Rotates `series` into body axes: accel and gyro by R_bs, the reference attitude to body -> world,
// q_body = q_ref * R_ref_from_imu * R_bs^T. Identity rotations are skipped, so an FRD series comes out bit for bit.
void rotate_to_body(ImuSeries& series, const Eigen::Matrix3d& imu_to_body, const Eigen::Matrix3d& ref_from_imu);

}  // namespace imubridge::estimator
