#pragma once
// What an import could not take as it is, in one report for every importer: rows or records skipped, values clipped
// to the frames' range, stretches of a file damaged. Each importer hands every problem to its options' `on_problem`
// (as mcap's onProblem does) and stores it as an event of its session (import_skipped, import_clipped,
// import_damaged); `imubridge import` prints the problems one way for every format.
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>

namespace imubridge::importers {

enum class ProblemKind { skipped, clipped, damaged };

// "skipped", "clipped", "damaged".
std::string_view problem_kind_name(ProblemKind kind);

struct ImportProblem {
  ProblemKind kind = ProblemKind::skipped;
  std::uint64_t count = 0;  // how many of `what`
  std::string what;         // what was affected, as counted: "sensor_combined records", "rows of FILE", "bytes of FILE"
  std::string why;          // the reason, and for damage what became of the rest
  std::optional<std::string>
      where{};  // where in the file, as far as the format says: "lines 8-9, 16-17", "at byte 4978"
  friend bool operator==(const ImportProblem&, const ImportProblem&) = default;
};

using ProblemCallback = std::function<void(const ImportProblem&)>;

// The problem as one line for people: "3 sensor_combined records skipped: not a finite number",
// "1 row of FILE clipped: accel beyond +-65.534 m/s^2 (line 12)".
std::string describe(const ImportProblem& problem);

}  // namespace imubridge::importers
