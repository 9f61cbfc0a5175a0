#pragma once
// What a model does for the velocity a user flies with: the drag-velocity estimator run with the model over a flight
// that has a reference, scored on the training and validation windows. identify and diagnose report it for every
// model they fit, in m/s beside the specific-force residual.
#include <Eigen/Core>
#include <cstddef>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "estimator/imu_series.hpp"
#include "estimator/params.hpp"
#include "identification/identify.hpp"

namespace imubridge::estimator {

struct VelocityScores {
  VelocityError train, validation;
  // VelocityEvaluation::gain_over_zero on the validation window (per second); empty when the model gives no velocity.
  std::vector<double> validation_gain_over_zero;
  // Non-empty when the estimator gives no velocity with this model (no drag law on either axis yet): the scores are
  // then zero velocity's, which is what such a model tells a user, and this says so.
  std::string note;
};

// Nothing without a reference. The filter's settings follow the parameters (config_for), as in run and replay.
// `validation_on_other_flights`: the validation window holds flights the model was not fitted on (a flight set's
// validating flights), which it flies as any new flight, transferred: their offset unknown (config_for).
std::optional<VelocityScores> score_velocity(const ImuSeries& series, const ModelParams& params, const Windows& windows,
                                             bool validation_on_other_flights = false);

// How well the drag-velocity filter run with a model predicts the accelerometer: the mean, over the samples of a
// window and both horizontal axes, of the Gaussian log-density of each innovation under the variance the filter gives
// it, -0.5 (nu^2 / S + log(2 pi S)). Needs no reference: without one, it is what an IMU-only model is judged by
// (docs/effects.md, "The rules"), as the velocity is with one. The filter's settings follow the parameters
// (config_for), as in run and replay.
struct FilterLikelihood {
  double train = 0.0, validation = 0.0;  // per measurement, nats
};
// Nothing when the model has no drag on a horizontal axis: the filter then reads no velocity from that accelerometer,
// and its likelihood would rank models that all fly zero velocity (as score_velocity gives none). Throws
// std::invalid_argument for parameters the estimator refuses or a window without estimates.
std::optional<FilterLikelihood> filter_log_likelihood(const ImuSeries& series, const ModelParams& params,
                                                      const Windows& windows);

// "Not moving": the reference's own RMS horizontal speed on each window, in the body frame `mounting` defines.
VelocityScores zero_velocity_scores(const ImuSeries& series, const Eigen::Vector3d& mounting, const Windows& windows);

// The fair anchor a reference makes possible (docs/results.md): per horizontal body axis, the least-squares line
// a = -k v + b between the accelerometer and the reference velocity, both averaged over 0.1-s blocks, the way PX4's
// drag-tuning script identifies its coefficient. A model must beat it to be worth its parameters; inverted sample by
// sample it would carry the airframe's vibration into the velocity, which nobody flies, so it is fitted and inverted
// on the blocks, and scored raw and smoothed by a 1-s centred moving average.
inline constexpr double kAnchorBlockSeconds = 0.1;
inline constexpr double kAnchorSmoothingSeconds = 1.0;
struct LeastSquaresDrag {
  // 1/s; 0 on an axis whose accelerometer does not fall with the velocity by more than kAnchorSlopeSignificance of its
  // standard errors: no drag is read there, and the anchor gives that axis zero velocity, as a user would, instead of
  // dividing by a slope that is noise (the X500's y: k = 0.031 1/s from 0.18 m/s of motion gave 11 m/s).
  Eigen::Vector2d k = Eigen::Vector2d::Zero();
  Eigen::Vector2d b = Eigen::Vector2d::Zero();  // m/s^2
  std::string note;                             // the axes without a drag read, and why; empty when both have one
};
inline constexpr double kAnchorSlopeSignificance = 2.0;
// Fitted on `train`. Throws std::invalid_argument without a reference, when an axis's training velocity does not vary,
// or when its accelerometer rises with the velocity beyond its standard errors (no drag: wrong axes, most likely).
LeastSquaresDrag fit_least_squares_drag(const ImuSeries& series, const TimeWindow& train);
// The fit inverted on `window` of a series (the one it was fitted on, or another flight), scored against the
// reference's block means, in the series' axes.
struct LeastSquaresDragScores {
  VelocityError raw, smoothed;
  std::size_t blocks = 0;
};
// Throws std::invalid_argument without a reference, or for a window with no whole block.
LeastSquaresDragScores score_least_squares_drag(const ImuSeries& series, const LeastSquaresDrag& fit,
                                                const TimeWindow& window);

// What a calibration does not know of a flight it was not fitted on (docs/estimator.md, "Honest variance"): the
// accelerometer offset std that makes the filter's normalised error squared 2 (its two axes: an honest variance) over
// flights with a reference that the calibration was not fitted on, each flown as a new flight (for_flight, its
// conditions left behind) and scored on its window. Bisection on the std between 0 and kMaxTransferOffsetStd.
inline constexpr double kMaxTransferOffsetStd = 5.0;  // m/s^2, half a g: beyond it no offset explains the error
struct TransferOffset {
  double offset_std = 0.0;    // m/s^2
  double nees_default = 0.0;  // the flights' NEES with kTransferredOffsetStd
  double nees = 0.0;          // with offset_std
  bool at_limit = false;      // NEES stays above 2 at kMaxTransferOffsetStd: the error is not an offset alone
  std::size_t flights = 0, samples = 0;
};
// Throws std::invalid_argument for no flights, a flight without a reference, or params without drag on either axis.
TransferOffset measure_transfer_offset(std::span<const ImuSeries> flights, std::span<const TimeWindow> windows,
                                       const ModelParams& params);

}  // namespace imubridge::estimator
