#pragma once
// Several flights for one fit (identify and diagnose, --session A,B,C --validate-session D,E): each session read,
// cut to its own window (--train of a fitting flight, --validate of a validating one, each of its own flight), and
// joined into one series with long gaps between them (identification/flight_set.hpp). One definition for both commands.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "cli/commands/session_windows.hpp"
#include "diagnose/residual_analysis.hpp"
#include "diagnose/signals.hpp"
#include "identification/flight_set.hpp"
#include "identification/identify.hpp"
#include "identification/velocity_scores.hpp"
#include "replay/session_series.hpp"
#include "store/store.hpp"

namespace imubridge::cli {

// --session and --validate-session, one definition for identify and diagnose. `fitted` says what is done with
// several flights ("fitted together", "diagnosed together").
inline void add_flight_set_options(CLI::App& cmd, std::string& sessions, std::optional<std::string>& validate,
                                   const char* fitted) {
  cmd.add_option("--session", sessions,
                 std::string("Session id; or several flights of one vehicle (1,2,3 or 1-3) ") + fitted +
                     ", with --validate-session")
      ->required();
  cmd.add_option("--validate-session", validate,
                 "Flights that validate what was fitted on --session's, not fitted on (4,5 or 4-9): the windows then "
                 "apply to each flight, --train to the fitting ones and --validate to these (default: each whole "
                 "flight)");
}

struct FlightSetReading {
  std::vector<std::int64_t> ids;  // the fitting flights, then the validating ones
  std::size_t fitting = 0;
  // Each as read, whole: a filter scoring a window runs from the flight's start; join() cuts each to its window.
  std::vector<estimator::ImuSeries> flights;
  std::vector<estimator::TimeWindow> windows;  // each flight's window, in its own time
  std::string identity;                        // "flights:imu:…,imu:…": what conditions fitted over the set name
  bool every_reference = true;
};

// Refuses a set without validating flights, or a flight both fitting and validating.
inline FlightSetReading read_flight_set(const store::Store& store, const std::vector<std::int64_t>& fit_ids,
                                        const std::vector<std::int64_t>& validate_ids,
                                        const replay::SessionSeriesOptions& reading, const WindowArgs& windows) {
  if (validate_ids.empty())
    throw std::invalid_argument(
        "several sessions fit one calibration: name the flights that validate it with --validate-session (e.g. "
        "--session 1,2,3 --validate-session 4,5)");
  for (const std::int64_t id : validate_ids) {
    if (std::find(fit_ids.begin(), fit_ids.end(), id) != fit_ids.end())
      throw std::invalid_argument("session " + std::to_string(id) +
                                  " both fits and validates: a calibration is validated on flights it was not "
                                  "fitted on");
  }
  FlightSetReading out;
  out.ids = fit_ids;
  out.ids.insert(out.ids.end(), validate_ids.begin(), validate_ids.end());
  out.fitting = fit_ids.size();
  out.identity = "flights:";
  for (std::size_t i = 0; i < out.ids.size(); ++i) {
    const bool fits = i < out.fitting;
    const replay::SessionSeries session = replay::read_session_series(store, out.ids[i], reading);
    for (const std::string& w : session.warnings)
      std::fprintf(stderr, "warning: session %lld: %s\n", static_cast<long long>(out.ids[i]), w.c_str());
    const estimator::TimeWindow span = percent_span(session, windows.in_flight).window;
    const std::optional<std::string>& text = fits ? windows.train : windows.validate;
    const estimator::TimeWindow window = estimator::clip(text ? estimator::parse_window(*text, span) : span,
                                                         session.series.t, fits ? "fit" : "validation");
    out.identity += (i == 0 ? "" : ",") + session.flight;
    out.every_reference = out.every_reference && session.series.reference.has_value();
    out.flights.push_back(session.series);
    out.windows.push_back(window);
  }
  return out;
}

struct JoinedFlights {
  estimator::FlightSet set;
  estimator::TimeWindow train, validate;  // the fitting flights' span and the validating flights', in the set's time
};

// Each flight cut to its window and joined. `for_filter`: the fit is the filter error method's, which averages
// blocks of samples by index, so each flight keeps whole blocks (none straddles two flights). Refuses fitting
// flights that hold less than estimator::kMinTrainSeconds.
inline JoinedFlights join(const FlightSetReading& r, bool for_filter) {
  std::vector<estimator::ImuSeries> cut;
  for (std::size_t i = 0; i < r.flights.size(); ++i) cut.push_back(estimator::cut(r.flights[i], r.windows[i]));
  const std::size_t align = for_filter ? diagnose::identification_block(diagnose::sample_rate_hz(cut.front().t)) : 1;
  JoinedFlights out{estimator::join_flights(cut, align), {}, {}};
  const std::vector<estimator::TimeWindow>& placed = out.set.placed;
  double fit_seconds = 0.0;
  for (std::size_t i = 0; i < r.fitting; ++i) fit_seconds += placed[i].end - placed[i].start;
  if (fit_seconds < estimator::kMinTrainSeconds) {
    char text[200];
    std::snprintf(text, sizeof text,
                  "the fitting flights hold %.1f s of data; identifying the drag needs at least %g s: give more or "
                  "longer flights",
                  fit_seconds, estimator::kMinTrainSeconds);
    throw std::invalid_argument(text);
  }
  out.train = {placed.front().start, placed[r.fitting - 1].end};
  out.validate = {placed[r.fitting].start, placed.back().end};
  return out;
}

// "sessions 1,2,3 (validation: 4,5)".
inline std::string describe_sessions(const FlightSetReading& r) {
  std::string out = "sessions ";
  for (std::size_t i = 0; i < r.ids.size(); ++i) {
    out += i == r.fitting ? " (validation: " : i > 0 ? "," : "";
    out += std::to_string(r.ids[i]);
  }
  return out + ")";
}

// Where each flight lies in the joined time, which the windows of a summary are in; to the summary's stream.
inline void print_flight_map(std::FILE* to, const FlightSetReading& r, const JoinedFlights& j) {
  std::fprintf(to, "the flights, one after another with %g s between them (the windows above are in this time):\n",
               estimator::kFlightGapSeconds);
  for (std::size_t i = 0; i < r.ids.size(); ++i) {
    const estimator::TimeWindow& here = j.set.placed[i];
    std::fprintf(to, "  session %lld %s: %.3f:%.3f s of its own, %.3f:%.3f s here\n", static_cast<long long>(r.ids[i]),
                 i < r.fitting ? "fits" : "validates", r.windows[i].start, r.windows[i].start + (here.end - here.start),
                 here.start, here.end);
  }
}

// The accelerometer offset a new flight carries, measured on the validating flights when each has a reference
// (estimator::measure_transfer_offset) and kept in `params` for the live filter; said on `to` either way.
inline void measure_transfer(const FlightSetReading& r, estimator::ModelParams& params, std::FILE* to) {
  const std::span<const estimator::ImuSeries> validating(r.flights.begin() + static_cast<std::ptrdiff_t>(r.fitting),
                                                         r.flights.end());
  const std::span<const estimator::TimeWindow> windows(r.windows.begin() + static_cast<std::ptrdiff_t>(r.fitting),
                                                       r.windows.end());
  if (!std::all_of(validating.begin(), validating.end(), [](const auto& f) { return f.reference.has_value(); })) {
    std::fprintf(to,
                 "the offset a new flight carries is not measured (a validating flight has no reference): the "
                 "filter counts the default %g m/s^2\n",
                 estimator::kTransferredOffsetStd);
    return;
  }
  try {
    const estimator::TransferOffset t = estimator::measure_transfer_offset(validating, windows, params);
    params.identification.transfer_offset_std = t.offset_std;
    std::fprintf(to,
                 "the offset a new flight carries, measured on the %zu validating flights: %.3g m/s^2 (their NEES "
                 "%.2f with the default %g m/s^2, %.2f with it; 2 is honest)%s\n",
                 t.flights, t.offset_std, t.nees_default, estimator::kTransferredOffsetStd, t.nees,
                 t.at_limit ? "; at its limit: the error on these flights is not an offset alone" : "");
  } catch (const std::invalid_argument& e) {
    std::fprintf(to, "the offset a new flight carries is not measured (%s): the filter counts the default %g m/s^2\n",
                 e.what(), estimator::kTransferredOffsetStd);
  }
}

}  // namespace imubridge::cli
