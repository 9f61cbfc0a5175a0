#pragma once
// What `imubridge diagnose --report DIR` writes: DIR/report.json for programs and DIR/report.html
// for people. Both come from a filled Diagnosis and nothing else; the same Diagnosis gives the same bytes.
#include <cstddef>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "diagnose/diagnosis.hpp"

namespace imubridge::diagnose {

// Peaks and correlations a residual summary keeps (strongest first); the full spectra and series stay out of the
// JSON so that it stays small.
inline constexpr std::size_t kReportTopEntries = 5;

// Every field of the Diagnosis, with the loop's outcome at the top level: "base", "steps", "final",
// "residual_white", "unexplained", plus "session", "model", "axes", "velocity_source", "train_window",
// "validation_window", "significance_rule", "last_candidates", "series". A residual analysis appears as a summary
// (rms, mean, Ljung-Box, top peaks and correlations, trend); numbers that are not finite (a standard error the
// covariance could not give) are null.
nlohmann::json report_json(const Diagnosis& diagnosis);

// "wind (with quadratic_drag)": an effect and the effects it needed (CandidateTrial::with, Step::with).
std::string with_needed(const std::string& effect, const std::vector<std::string>& with);

// One line a person reads first: the velocity error before and after the loop (when there is a reference), the
// specific-force residual beside it, and the effects added. The report's summary and the command's stderr share it.
std::string summary_line(const Diagnosis& diagnosis);

// report_json(), indented, to `file`, whole or not at all. Throws std::runtime_error when the file cannot be
// written, leaving an earlier one as it was.
void write_report_json(const Diagnosis& diagnosis, const std::filesystem::path& file);

// dir/report.html, one self-contained page (no network, no script): the summary, the model search step by step,
// what is left unexplained, the final parameters, the candidates of each step, and plots drawn by gnuplot and
// inlined as SVG (measured vs model before and after, residual over time, residual spectrum, convergence of each
// fit). Without gnuplot the page has the tables and a note, and a warning is logged: a report without plots is
// still a report. Creates `dir` if needed; throws std::runtime_error when the page cannot be written.
void write_report_html(const Diagnosis& diagnosis, const std::filesystem::path& dir);

}  // namespace imubridge::diagnose
