#pragma once
// Identification of the accelerometer model from a flight (docs/identification.md): the fit and validation windows,
// the data preparation (angular acceleration, the drag term's velocity), running a method (the paper's GA,
// Levenberg-Marquardt, or the GA polished by LM) and the results that go into PARAMS.json. Also the evaluation of
// the drag-velocity estimator against a reference, which is how identified parameters are judged.
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "estimator/drag_velocity.hpp"
#include "estimator/imu_series.hpp"
#include "estimator/paper_model.hpp"
#include "estimator/params.hpp"
#include "identification/cost_functors.hpp"
#include "identification/ga.hpp"
#include "identification/identify_choices.hpp"
#include "identification/least_squares.hpp"

namespace imubridge::estimator {

// The paper's split: the first 33 s identify, the rest validate (section VII).
inline constexpr double kPaperTrainSeconds = 33.0;

struct IdentifyOptions {
  ModelKind model = ModelKind::paper;
  Method method = Method::lm;
  VelocitySource velocity = VelocitySource::eq12;
  std::optional<TimeWindow> train;     // default [0, 33) s
  std::optional<TimeWindow> validate;  // default from the end of `train` to the end of the data
  GaOptions ga;
  FullHold hold;  // 3-D model: blocks kept at their defaults
  // s, see smoothed_derivative(). About 30 ms, but not a multiple of the usual sample periods (1/100 .. 1/1000 s),
  // so that no sample sits on the window's edge, where rounding in the timestamps would decide whether it counts.
  double derivative_half_window = 0.0315;
};

// ---- windows ----

// "T0:T1" in seconds of session time; "T0:" runs to the end of the data. With a "%" on either end both ends are
// percentages of the data's span instead ("0:40%" is its first 40 %, "40%:" the rest), which needs the samples'
// times `t` to resolve. Throws std::invalid_argument otherwise.
TimeWindow parse_window(std::string_view text, std::span<const double> t = {});
// The same with percentages of `span` instead of the data's (e.g. the flight: identification/flight_span.hpp).
TimeWindow parse_window(std::string_view text, const TimeWindow& span);
// The data's span: from the first sample to the end of the last, [t_0, t_last + last period).
TimeWindow data_span(std::span<const double> t);

// `w` clipped to the data, [t_0, t_last + last period). Throws std::invalid_argument naming the window (`what`:
// "fit", "validation", ...) and the data's span when nothing is left.
TimeWindow clip(const TimeWindow& w, std::span<const double> t, const char* what);

struct Windows {
  TimeWindow train, validate;
};
// The windows clipped to the data, [t_0, t_last + last period). Throws std::invalid_argument naming the window and
// the data's span when one is empty after clipping.
Windows resolve_windows(std::span<const double> t, const std::optional<TimeWindow>& train,
                        const std::optional<TimeWindow>& validate);

// A multirotor's velocity answers a tilt within about 3/k, 10 s at a typical k = 0.3 1/s: a training window shorter
// than that cannot tell the drag from the rest of the model. Throws std::invalid_argument giving the window's length.
inline constexpr double kMinTrainSeconds = 10.0;
void require_trainable(const TimeWindow& train);

// The samples with window.start <= t < window.end (samples are in time order).
template <typename Sample>
std::span<const Sample> select(const std::vector<Sample>& samples, const TimeWindow& window) {
  const auto before = [](const Sample& s, double t) { return s.t < t; };
  const auto first = std::lower_bound(samples.begin(), samples.end(), window.start, before);
  return {first, std::lower_bound(first, samples.end(), window.end, before)};
}

// ---- data preparation ----

// Offline angular acceleration: at each sample, the slope of a cubic least-squares fit to the samples within
// +-half_window of it, against their own timestamps (the degree drops where fewer than 4 samples are in reach: ends,
// gaps). Its centre is the sample itself, so there is no delay. A cubic passes the manoeuvres' content that a
// straight-line fit of the same width would flatten, and averages the gyro's noise far better than the central
// difference; docs/identification.md has the numbers. Throws std::invalid_argument for lengths that differ or a
// half window that is not positive.
std::vector<Eigen::Vector3d> smoothed_derivative(std::span<const double> t, std::span<const Eigen::Vector3d> x,
                                                 double half_window);

// One axis's eq. (14) signals: omega, theta, f as prepare_paper_axis(), omega_dot from smoothed_derivative(), v from
// eq. (12) or from the reference (minus the body-axis velocity along the axis: the paper's sign).
std::vector<PaperSample> prepare_paper(const ImuSeries& series, PaperAxis axis, VelocitySource velocity,
                                       double half_window);
// The 3-D model's inputs: the body-axis horizontal velocity from dead_reckon() (gyro taken as body rates, T = g:
// eq. 12's generalisation) or from the reference.
std::vector<FullSample> prepare_full(const ImuSeries& series, VelocitySource velocity, double half_window);

// Eq. (12)'s integral has nothing that holds it: a gyro bias or a tilt error makes it grow without bound, and a drag
// fitted to it fits the drift. Its drift over `window`: the change, across the window, of the least-squares line
// through its horizontal world velocity (the 3-D integral, gyro turned by `mounting`, from the series' first
// sample), horizontal norm, m/s. A flight's own velocity seldom trends that way for long.
double eq12_drift(const ImuSeries& series, const Eigen::Vector3d& mounting, const TimeWindow& window);
// Beyond this drift (m/s) identify and diagnose warn that eq. (12)'s velocity is not the flight's.
inline constexpr double kEq12DriftLimit = 5.0;
// The warning, when eq12_drift() exceeds kEq12DriftLimit; nullopt otherwise.
std::optional<std::string> eq12_drift_warning(const ImuSeries& series, const Eigen::Vector3d& mounting,
                                              const TimeWindow& window);

// ---- running a method ----

// One fitted group of parameters: a paper axis ("paper.x", "paper.y") or the 3-D model ("full").
struct FitReport {
  std::string name{};
  Uncertainty uncertainty{};          // parameter names relative to `name`
  std::vector<double> convergence{};  // GA: best OF after each generation (the paper's Fig. 12); else empty
  std::optional<SolverReport> lm{};   // when LM ran
  double fit_objective = 0.0;         // OF, eq. (15), on the fit window, m/s^2
  std::size_t fit_samples = 0, validation_samples = 0;
  double solve_seconds = 0.0;  // wall time of the optimiser(s) alone
};

struct IdentifyResult {
  ModelParams params;  // values, and in params.identification the method, seed, windows, std errors and RMSEs
  std::vector<FitReport> fits;
};

// The paper model fits both axes (pitch -> paper.x, roll -> paper.y) and derives params.full from them
// (full_from_paper) for the live estimator; the 3-D model fills params.full. Throws std::invalid_argument for an
// invalid series, empty windows, too few samples, or velocity from a reference the series does not have.
IdentifyResult identify(const ImuSeries& series, const IdentifyOptions& options);

// The GA's search box for one paper axis: r in [0, 0.5] m, beta in [-180, 180] deg, alpha in [-15, 15] deg,
// mu in [0, 1] 1/m.
GaBounds paper_bounds();

// The 3-D parameters the two paper axes describe: lever arm (r_x cos b_x, r_y cos b_y, mean of -r sin b),
// mounting (-alpha_y, alpha_x, 0), quadratic drag (mu_x, mu_y), no linear drag, no bias (docs/identification.md).
FullModelParams full_from_paper(const PaperAxisParams& pitch, const PaperAxisParams& roll);

// ---- judging the drag-velocity estimator ----

// RMSE against the reference's body-axis horizontal velocity, m/s, per axis and of the horizontal error vector.
struct VelocityError {
  Eigen::Vector2d axis = Eigen::Vector2d::Zero();
  double horizontal = 0.0;
};

// Sums squared errors sample by sample into a VelocityError.
struct VelocityErrorSum {
  Eigen::Vector2d sums = Eigen::Vector2d::Zero();
  Eigen::Vector2d squares = Eigen::Vector2d::Zero();
  std::size_t count = 0;
  void add(const Eigen::Vector2d& error) { sums += error, squares += error.cwiseAbs2(), ++count; }
  Eigen::Vector2d mean() const { return sums / samples(); }
  VelocityError rmse() const { return root(squares / samples()); }
  // The RMSE about the mean error: what is left once the window's constant error is taken out.
  VelocityError rmse_about_mean() const { return root((squares / samples() - mean().cwiseAbs2()).cwiseMax(0.0)); }

 private:
  double samples() const { return static_cast<double>(std::max<std::size_t>(count, 1)); }
  static VelocityError root(const Eigen::Vector2d& mean_square) {
    return {mean_square.cwiseSqrt(), std::sqrt(mean_square.sum())};
  }
};

inline constexpr double kGainBlockSeconds = 1.0;
struct VelocityEvaluation {
  TimeWindow window;
  std::size_t samples = 0;  // samples scored: in the window and with an estimate
  VelocityError estimator;  // the drag-velocity Kalman filter
  VelocityError inversion;  // the drag law inverted sample by sample (the filter's measurement)
  VelocityError eq12;       // open-loop integration: dead_reckon(), eq. (12)'s 3-D generalisation
  VelocityError zero;       // "not moving": the reference's own RMS speed
  // The filter's error split in two: its mean over the window (m/s, per axis), and the RMSE left about that mean, what
  // the filter would score if the flight's constant were known. A calibration carried to another flight is off by a
  // constant it cannot see from the IMU on a steady heading (the wind along the flight, the accelerometer's offset:
  // docs/estimator.md); needing the reference, this is a bound, not a result.
  Eigen::Vector2d estimator_mean_error = Eigen::Vector2d::Zero();
  VelocityError estimator_constant_known;
  // Whether the filter's variance is honest: the mean over scored samples of its normalised error squared,
  // sum over x, y of (v - v_ref)^2 / v_var. A filter whose variance says what its error is gives 2 (the axes); more
  // means it claims more certainty than it has.
  double nees = 0.0;
  // How much nearer the reference the filter is than zero velocity, |v_ref|^2 - |v - v_ref|^2 (m^2/s^2), averaged over
  // each kGainBlockSeconds of the window that has scored samples, in time order. Its mean is about zero velocity's mean
  // square error less the filter's; a paired test on it tells a model that flies better than "not moving" from one
  // that does so by chance (diagnose's velocity_gain_test). Blocks, not samples: a day at 1 kHz stays small.
  std::vector<double> gain_over_zero;
  DragVelocityCounters counters;
};

// Runs DragVelocityEstimator over the whole series (its state needs the flight's start), fusing rest where the
// series' land detector says landed, and scores the samples in `window` (default: all). Every row is scored in the
// estimator's body frame: the reference's velocity, in the series' axes, is turned by the mounting (R_bs =
// Exp(mounting), IMU -> body) first. Throws std::invalid_argument without a reference, for params the estimator
// refuses, for a model without drag on either axis (no velocity to score; an axis without drag beside one with it reads
// rest and is scored so) or for an empty window.
VelocityEvaluation evaluate_velocity(const ImuSeries& series, const FullModelParams& params,
                                     const std::optional<TimeWindow>& window = std::nullopt,
                                     const DragVelocityConfig& config = {});
// The same for several windows from one run of the estimator, in their order.
std::vector<VelocityEvaluation> evaluate_velocity(const ImuSeries& series, const FullModelParams& params,
                                                  std::span<const TimeWindow> windows,
                                                  const DragVelocityConfig& config = {});

}  // namespace imubridge::estimator
