#pragma once
// A zero-phase low-pass for comparing model and measurement in the band the model describes: a second-order
// Butterworth (bilinear transform) run forward, then backward (filtfilt), so the pair is fourth-order with no delay.
// A rigid-body model has nothing to say about an airframe's broadband vibration, which on a real multirotor can
// carry most of the accelerometer's power (docs/effects.md, "Band limit").
#include <span>

namespace imubridge::diagnose {

// Filters `x` in place. Each pass starts in the steady state of its first sample, so a constant passes unchanged and
// the ends carry no start-up transient. Throws std::invalid_argument unless 0 < cutoff_hz < rate_hz / 2.
void zero_phase_lowpass(std::span<double> x, double cutoff_hz, double rate_hz);

}  // namespace imubridge::diagnose
