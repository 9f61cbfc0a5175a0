#pragma once
// What a percentage in --train, --validate or --window is a percentage of: the session, or with --in-flight the part
// the vehicle flies (estimator::detect_flight), said on stderr. identify, diagnose and evaluate share it.
#include <cstdio>
#include <optional>
#include <string>

#include "estimator/flight_span.hpp"
#include "estimator/identify.hpp"

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

}  // namespace imubridge::cli
