#pragma once
// Numeric tables as instruments, hand edits and spreadsheets leave them: LF or CRLF line endings, comment and blank
// lines, rows cut short, text where numbers belong, timestamps in scientific notation. Every row is either used or
// skipped with its line number and a reason; nothing in a file's content is fatal.
#include <cstdint>
#include <functional>
#include <istream>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace imubridge::replay {

// Line numbers (from 1) grouped by what was wrong with their rows.
struct LinesByReason {
  std::map<std::string, std::vector<std::int64_t>> lines{};

  void add(std::int64_t line, std::string reason) { lines[std::move(reason)].push_back(line); }
  std::uint64_t count() const;
  // One reason's rows for people: "6 rows: empty field (lines 36822-36827)".
  static std::string describe(const std::string& reason, std::span<const std::int64_t> lines);
  // describe() for every reason.
  std::vector<std::string> summary() const;
};

struct TableLayout {
  char separator = ',';        // ',' or ' ' (any run of spaces and tabs)
  int time_unit_exponent = 0;  // the first column's unit in powers of ten of a nanosecond: ns 0, s 9
  std::size_t min_fields = 1, max_fields = 1;
};

struct TableRow {
  std::int64_t line = 0;
  std::int64_t t_ns = 0;
  std::vector<double> values;  // the fields after the timestamp, all finite
};

// Returns the reason to skip a row it cannot use, or nothing when it took the row.
using RowHandler = std::function<std::optional<std::string>(const TableRow&)>;

// Hands every well-formed row whose timestamp is after the previous taken row's to `take`; records every other row
// in `skipped`. Blank lines and lines starting with '#' (headers) are no rows.
void read_table(std::istream& in, const TableLayout& layout, const RowHandler& take, LinesByReason& skipped);

// Increasing numbers as ranges, for people: {3, 4, 5, 9} -> "3-5, 9".
std::string format_ranges(std::span<const std::int64_t> increasing);

// An exact decimal ("-12", "1403636580.83856", "1.40363657975856E+018") times 10^exponent, to the nearest integer
// (halves away from zero), without the rounding a double would add. Nothing if it is not such a number or does not
// fit 64 bits.
std::optional<std::int64_t> parse_scaled_integer(std::string_view text, int exponent);

// later - earlier for timestamps in order (later >= earlier), exact over the whole range: the rows' stamps may lie
// further apart than an int64 difference holds (2^63 ns, 292 years).
inline std::uint64_t elapsed_ns(std::int64_t earlier, std::int64_t later) {
  return static_cast<std::uint64_t>(later) - static_cast<std::uint64_t>(earlier);
}

}  // namespace imubridge::replay
