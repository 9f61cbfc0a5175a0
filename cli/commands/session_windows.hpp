#pragma once
// The fit and validation windows as identify and diagnose take them (--train, --validate, --in-flight), and the
// plausibility limits (--limit): one definition of the options and their help. What a percentage is a percentage of
// is the session, or with --in-flight the part the vehicle flies (the log's land detector, else
// estimator::detect_flight), said on stderr; evaluate
// shares that too.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <optional>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "identification/flight_span.hpp"
#include "identification/identify.hpp"
#include "identification/plausibility.hpp"
#include "replay/session_series.hpp"

namespace imubridge::cli {

// What percentages are of: the flight when --in-flight found one (said on stderr), else the whole session.
struct PercentSpan {
  estimator::TimeWindow window;
  std::optional<estimator::TimeWindow> flight;
};

// The flight by the log's own land detector when the session has one (import ulog stores its takeoff and landing),
// else by the rotors' vibration (estimator::detect_flight); which one is said.
inline PercentSpan percent_span(const replay::SessionSeries& session, bool in_flight) {
  const estimator::ImuSeries& series = session.series;
  const estimator::TimeWindow whole = estimator::data_span(series.t);
  if (!in_flight) return {whole, std::nullopt};
  if (session.airborne) {
    if (const auto flight = estimator::flight_from_land_detector(*session.airborne, whole)) {
      std::fprintf(stderr, "%s: percentages are of it\n", flight->description.c_str());
      return {flight->window, flight->window};
    }
    std::fprintf(stderr,
                 "warning: --in-flight: the log's land detector has no flight within the data; trying the rotors' "
                 "vibration\n");
  }
  if (const std::optional<estimator::FlightSpan> flight = estimator::detect_flight(series)) {
    std::fprintf(stderr, "%s: percentages are of it\n", flight->description.c_str());
    return {flight->window, flight->window};
  }
  std::fprintf(stderr,
               "warning: --in-flight: no part at rest to tell the flight from (the accelerometer's vibration level "
               "hardly changes); percentages are of the whole session\n");
  return {whole, std::nullopt};
}

// A window in seconds (or the default one) is of the session even with --in-flight: a fit that runs mostly on the
// ground identifies nothing, so say how much of it lies outside the detected flight.
inline void warn_outside_flight(const char* what, const estimator::TimeWindow& window,
                                const estimator::TimeWindow& flight, const estimator::TimeWindow& data) {
  const std::optional<double> share = estimator::share_in_flight(window, flight, data);
  if (!share || *share >= 0.9) return;  // an empty window is refused by resolve_windows in its own words
  std::fprintf(stderr,
               "warning: --in-flight: the %s window %.1f-%.1f s is %.0f %% in the flight (%.1f-%.1f s); give it in "
               "percent of the flight (e.g. --train 0:40%% --validate 40%%:)\n",
               what, std::max(window.start, data.start), std::min(window.end, data.end), 100.0 * *share, flight.start,
               flight.end);
}

inline void add_in_flight_flag(CLI::App& cmd, bool& in_flight) {
  cmd.add_flag("--in-flight", in_flight,
               "Percentages in the windows are of the flight (by the log's land detector when the session has "
               "one, else from the rotors' vibration), at both ends, not the session");
}

struct WindowArgs {
  std::optional<std::string> train, validate;
  bool in_flight = false;

  // The windows, resolved against the session (nullopt: the command's default; with a flight, the validation
  // window's default ends where the flight does).
  std::pair<std::optional<estimator::TimeWindow>, std::optional<estimator::TimeWindow>> resolve(
      const replay::SessionSeries& session) const {
    const estimator::ImuSeries& series = session.series;
    const PercentSpan span = percent_span(session, in_flight);
    std::pair<std::optional<estimator::TimeWindow>, std::optional<estimator::TimeWindow>> out;
    if (train) out.first = estimator::parse_window(*train, span.window);
    if (validate) out.second = estimator::parse_window(*validate, span.window);
    if (span.flight && out.first && !out.second && out.first->end < span.flight->end)
      out.second = estimator::TimeWindow{out.first->end, span.flight->end};
    if (span.flight) {
      const estimator::TimeWindow data = estimator::data_span(series.t);
      const estimator::TimeWindow fit =
          out.first.value_or(estimator::TimeWindow{0.0, estimator::kPaperTrainSeconds});  // identify's default
      warn_outside_flight("fit", fit, *span.flight, data);
      warn_outside_flight("validation", out.second.value_or(estimator::TimeWindow{fit.end, data.end}), *span.flight,
                          data);
    }
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
  // From the limits' table, so a limit that refuses a fit is always one --help names.
  cmd.add_option("--limit", limits,
                 "Override a plausibility limit, NAME=VALUE (repeatable): " + estimator::limit_help());
}

inline estimator::PlausibilityLimits plausibility_limits(const std::vector<std::string>& overrides) {
  estimator::PlausibilityLimits limits;
  for (const std::string& o : overrides) estimator::override_limit(limits, o);
  return limits;
}

}  // namespace imubridge::cli
