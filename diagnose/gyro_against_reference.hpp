// The gyro's bias measured against a reference attitude. With a reference, a gyro bias hardly shows in the specific
// force (only through the lever arm's centripetal term, r cos(beta) (omega - b)^2), so a fit of it on the residual
// wanders; the reference's attitude shows it directly: over each short span, the rotation the gyro integrates less
// the one the reference turns through (docs/effects.md, "The reference attitude's test").
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <optional>

namespace imubridge::diagnose {

struct Signals;

// Short enough that the bias turns little with the body within a span (first order), long enough that the reference's
// jitter, divided by the span, stays small.
inline constexpr double kGyroSpanSeconds = 0.25;
// Fewer spans than this (per parameter fitted: 4 per axis) tell nothing.
inline constexpr std::size_t kGyroMinSpans = 16;

struct GyroAgainstReference {
  // rad/s, the series' axes: what the gyro reads beyond the reference's turn.
  Eigen::Vector3d bias = Eigen::Vector3d::Zero();
  // rad/s, corrected for the spans' correlation.
  Eigen::Vector3d std_error = Eigen::Vector3d::Zero();
  // Wald: the sum over the axes of (bias / std_error)^2; p_value that the gyro has no bias, from chi-square(3).
  double statistic = 0.0;
  double p_value = 1.0;
  std::size_t spans = 0;
};

// Over samples [first, first + count) of `signals` (which need a reference): per span, the gyro's turn less the
// reference's, e = (Log(R_gyro) - Log(R_ref)) / dt, regressed per axis on the reference's mean rate, e = b + m . omega,
// so that a reference frame turned slightly from the gyro's (the mounting the model fits, a scale error) reads as m and
// not as a bias; b is the bias. nullopt without a reference or with fewer than kGyroMinSpans spans.
std::optional<GyroAgainstReference> gyro_against_reference(const Signals& signals, std::size_t first,
                                                           std::size_t count);

}  // namespace imubridge::diagnose
