#pragma once
// The fit and validation windows as identify and diagnose take them (--train, --validate, --in-flight), and the
// plausibility limits (--limit): one definition of the options and their help. What a percentage is a percentage of
// is the session, or with --in-flight the part the vehicle flies (estimator::detect_flight), said on stderr; evaluate
// shares that too.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <optional>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "estimator/flight_span.hpp"
#include "estimator/identify.hpp"
#include "estimator/plausibility.hpp"

namespace imubridge::cli {

inline estimator::TimeWindow percent_span(const estimator::ImuSeries& series, bool in_flight) {
  const estimator::TimeWindow whole = estimator::data_span(series.t);
  if (!in_flight) return whole;
  if (const std::optional<estimator::FlightSpan> flight = estimator::detect_flight(series)) {
    std::fprintf(stderr, "%s: percentages are of it\n", flight->description.c_str());
    return flight->window;
  }
  std::fprintf(stderr,
               "warning: --in-flight: no part at rest to tell the flight from (the accelerometer's vibration level "
               "hardly changes); percentages are of the whole session\n");
  return whole;
}

inline void add_in_flight_flag(CLI::App& cmd, bool& in_flight) {
  cmd.add_flag("--in-flight", in_flight,
               "Percentages in the windows are of the flight (detected from the rotors' vibration), not the session");
}

struct WindowArgs {
  std::optional<std::string> train, validate;
  bool in_flight = false;

  // The windows, resolved against the series (nullopt: the command's default).
  std::pair<std::optional<estimator::TimeWindow>, std::optional<estimator::TimeWindow>> resolve(
      const estimator::ImuSeries& series) const {
    const estimator::TimeWindow span = percent_span(series, in_flight);
    std::pair<std::optional<estimator::TimeWindow>, std::optional<estimator::TimeWindow>> out;
    if (train) out.first = estimator::parse_window(*train, span);
    if (validate) out.second = estimator::parse_window(*validate, span);
    return out;
  }
};

inline void add_window_options(CLI::App& cmd, WindowArgs& w) {
  cmd.add_option("--train", w.train,
                 "Fit window T0:T1 in seconds from the session start, or in percent of the session (0:40%) "
                 "(default 0:33)");
  cmd.add_option("--validate", w.validate,
                 "Validation window T0:T1, seconds or percent (40%:) (default: from the end of --train on)");
  add_in_flight_flag(cmd, w.in_flight);
}

inline void add_limit_option(CLI::App& cmd, std::vector<std::string>& limits) {
  cmd.add_option("--limit", limits,
                 "Override a plausibility limit, NAME=VALUE (repeatable): lever_arm (m), wind (m/s), accel_scale, "
                 "accel_cross, gyro_bias (rad/s), accel_bias (m/s^2), time_offset (s)");
}

inline estimator::PlausibilityLimits plausibility_limits(const std::vector<std::string>& overrides) {
  estimator::PlausibilityLimits limits;
  for (const std::string& o : overrides) estimator::override_limit(limits, o);
  return limits;
}

}  // namespace imubridge::cli
