#pragma once
// A recorded session as the estimator's input: one link's samples as an estimator::ImuSeries, timed by the IMU's
// own clock, with the session's reference trajectory interpolated at each sample when asked for
// (docs/identification.md, "Session time").
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "estimator/imu_axes.hpp"
#include "estimator/imu_series.hpp"
#include "estimator/params.hpp"
#include "estimator/reference_delay.hpp"
#include "store/store.hpp"

namespace imubridge::replay {

// Whether the reference trajectory is interpolated at every sample.
enum class ReferenceUse {
  none,
  required,      // a session without one is an error
  when_present,  // used if the store holds at least two poses of the session, left out otherwise
};

struct SessionSeriesOptions {
  std::optional<std::int64_t> link{};  // default: the session's link with the most samples
  ReferenceUse reference = ReferenceUse::none;
  // The IMU's axes (estimator::parse_imu_axes spelling), overriding what the link's recorded config declares
  // ("auto" when it declares nothing).
  std::optional<std::string> imu_axes{};
  // The reference velocity's delay behind the IMU, s (docs/identification.md, "Reference delay"): declared, the
  // reference is shifted by it (0: not shifted); else, with estimate_reference_delay, estimated
  // (estimator::estimate_reference_delay) and shifted by when the estimate is usable.
  std::optional<double> reference_delay{};
  bool estimate_reference_delay = false;
};

// What was read and what was left out, and why. Nothing is dropped silently.
struct SessionSeriesCounts {
  std::uint64_t samples = 0;                 // the link's samples in the store
  std::uint64_t non_finite = 0;              // dropped: a NaN or infinite accelerometer or gyro value
  std::uint64_t time_not_increasing = 0;     // dropped: device time not after the previous kept sample's
  std::uint64_t outside_reference = 0;       // dropped: received (shifted by the reference delay) before the first
                                             // or after the last pose
  std::uint64_t reference_rows = 0;          // poses in the store
  std::uint64_t reference_rows_dropped = 0;  // non-finite, zero quaternion, or time not after the previous pose
};

struct SessionSeries {
  estimator::ImuSeries series;  // t: seconds since the link's first sample, from device_time_us; FRD body axes
  std::int64_t link_id = 0;
  // The flight's identity (estimator::flight_identity) taken from the link's usable samples as stored, before the
  // reference's span or the axes change them: the same however the session is read, so that a PARAMS.json fitted
  // with the reference knows its own flight when it is replayed without one (estimator::for_flight).
  std::string flight;
  SessionSeriesCounts counts;
  estimator::AxesResolution axes;                                    // how the IMU's axes were turned into the body's
  std::optional<estimator::ReferenceAlignment> reference_alignment;  // with a reference: its attitude's frame
  std::optional<estimator::ReferenceDelay> reference_delay;          // the estimate, when one was made
  double reference_shift_s = 0.0;    // the reference velocity at sample time t is the reference's at t + this
  std::string reference_delay_line;  // "reference delay: ..." for people; empty when the delay was not looked at
  // When the log's own land detector says the vehicle flew (the session's takeoff and landing events, as `import
  // ulog` stores them), on the series' clock; an open end is infinite. nullopt: the session has no such events. The
  // spans between them are the series' `landed`.
  std::optional<std::vector<estimator::TimeWindow>> airborne;
  std::vector<std::string> warnings;  // one line each, without a "warning: " prefix: axes mismatch, notes
};

// Reads `session` from `store`. The series' t is the IMU's device_time_us, in seconds from the link's first kept
// sample. The reference's t_ns is on the session's monotonic clock, as the samples' recv_mono_ns are, so each sample
// takes the reference interpolated at its recv_mono_ns: velocity linearly, attitude by slerp. Poses without a
// velocity get one from the central difference of the positions. Throws std::invalid_argument for an unknown
// session or link, a link without samples, or a reference required and missing (fewer than two usable poses), or
// present in the store (two poses or more) and unusable, or IMU axes that do not parse.
//
// The series comes out in the vehicle's FRD body axes (docs/estimator.md, "IMU axes"): the declared axes (options,
// else the link's recorded config, else auto) are resolved against gravity detected in the samples, accel and gyro
// are rotated by R_bs, and a reference attitude is re-expressed body -> NED after estimating whether it was the
// IMU's or the body's. An FRD session with an FRD (or body) reference comes out bit for bit as read.
//
// With a reference delay (declared or estimated and usable), each sample takes the reference velocity (and only the
// velocity: an autopilot's attitude is current) interpolated at its recv_mono_ns plus the delay; samples whose
// shifted time falls outside the reference are dropped and counted in outside_reference. A declared delay outside
// +-10 s is refused (std::invalid_argument).
SessionSeries read_session_series(const store::Store& store, std::int64_t session,
                                  const SessionSeriesOptions& options = {});

}  // namespace imubridge::replay
