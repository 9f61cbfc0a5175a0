#pragma once
// --reference-delay as identify, diagnose and evaluate take it: one definition of the option, what it does to the
// session's reading and the line it prints (docs/identification.md, "Reference delay").
#include <CLI/CLI.hpp>
#include <cstdio>
#include <optional>

#include "replay/session_series.hpp"

namespace imubridge::cli {

inline void add_reference_delay_option(CLI::App& cmd, std::optional<double>& delay) {
  cmd.add_option("--reference-delay", delay,
                 "The reference velocity's delay behind the IMU, s: the reference is shifted by it (0: not shifted); "
                 "default: estimated from the data, and shifted by when the estimate is clear");
}

// The reading options for it: declared, or estimated.
inline void set_reference_delay(replay::SessionSeriesOptions& options, const std::optional<double>& declared) {
  options.reference_delay = declared;
  options.estimate_reference_delay = !declared;
}

// "reference delay: ..." on stderr when the session's reference was read.
inline void print_reference_delay(const replay::SessionSeries& session) {
  if (!session.reference_delay_line.empty()) std::fprintf(stderr, "%s\n", session.reference_delay_line.c_str());
}

// What PARAMS.json records: the shift the reference was fitted and scored with, when there was a reference.
inline std::optional<double> recorded_reference_delay(const replay::SessionSeries& session) {
  if (!session.series.reference) return std::nullopt;
  return session.reference_shift_s;
}

}  // namespace imubridge::cli
