#include "replay/text_table.hpp"

#include <cctype>
#include <charconv>
#include <cmath>
#include <limits>

namespace imubridge::replay {
namespace {

std::string_view trim(std::string_view s) {
  const auto first = s.find_first_not_of(" \t\r");
  if (first == std::string_view::npos) return {};
  return s.substr(first, s.find_last_not_of(" \t\r") - first + 1);
}

std::vector<std::string_view> split(std::string_view line, char separator) {
  std::vector<std::string_view> fields;
  if (separator == ' ') {
    for (std::size_t i = line.find_first_not_of(" \t"); i != std::string_view::npos;
         i = line.find_first_not_of(" \t", i)) {
      const std::size_t end = std::min(line.find_first_of(" \t", i), line.size());
      fields.push_back(line.substr(i, end - i));
      i = end;
    }
    return fields;
  }
  for (std::size_t start = 0;;) {
    const std::size_t end = line.find(separator, start);
    fields.push_back(trim(line.substr(start, end - start)));
    if (end == std::string_view::npos) return fields;
    start = end + 1;
  }
}

std::optional<double> parse_finite(std::string_view text) {
  if (text.starts_with('+')) text.remove_prefix(1);  // from_chars takes no plus sign
  double value = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (error != std::errc() || end != text.data() + text.size() || !std::isfinite(value)) return std::nullopt;
  return value;
}

std::string field_count_reason(std::size_t n, const TableLayout& layout) {
  std::string expected = std::to_string(layout.min_fields);
  if (layout.max_fields != layout.min_fields) {
    expected = layout.max_fields == std::numeric_limits<std::size_t>::max()
                   ? "at least " + expected
                   : expected + " to " + std::to_string(layout.max_fields);
  }
  return std::to_string(n) + (n == 1 ? " field" : " fields") + ", expected " + expected;
}

// The row, or why it cannot be one.
std::optional<std::string> parse_row(const std::vector<std::string_view>& fields, const TableLayout& layout,
                                     TableRow& row) {
  if (fields.size() < layout.min_fields || fields.size() > layout.max_fields) {
    return field_count_reason(fields.size(), layout);
  }
  // The first bad field, in reading order, names the reason.
  if (fields[0].empty()) return "empty field";
  const auto t_ns = parse_scaled_integer(fields[0], layout.time_unit_exponent);
  if (!t_ns) return parse_finite(fields[0]) ? "timestamp out of range" : "not a finite number";
  row.t_ns = *t_ns;
  row.values.clear();
  for (std::size_t i = 1; i < fields.size(); ++i) {
    if (fields[i].empty()) return "empty field";
    const auto value = parse_finite(fields[i]);
    if (!value) return "not a finite number";
    row.values.push_back(*value);
  }
  return std::nullopt;
}

}  // namespace

std::uint64_t LinesByReason::count() const {
  std::uint64_t n = 0;
  for (const auto& [reason, at] : lines) n += at.size();
  return n;
}

std::string LinesByReason::describe(const std::string& reason, std::span<const std::int64_t> lines) {
  const bool one = lines.size() == 1;
  return std::to_string(lines.size()) + (one ? " row: " : " rows: ") + reason + (one ? " (line " : " (lines ") +
         format_ranges(lines) + ")";
}

std::vector<std::string> LinesByReason::summary() const {
  std::vector<std::string> out;
  for (const auto& [reason, at] : lines) out.push_back(describe(reason, at));
  return out;
}

std::string format_ranges(std::span<const std::int64_t> increasing) {
  std::string out;
  for (std::size_t i = 0; i < increasing.size();) {
    std::size_t j = i;
    while (j + 1 < increasing.size() && increasing[j + 1] == increasing[j] + 1) ++j;
    if (!out.empty()) out += ", ";
    out += std::to_string(increasing[i]);
    if (j > i) out += "-" + std::to_string(increasing[j]);
    i = j + 1;
  }
  return out;
}

void read_table(std::istream& in, const TableLayout& layout, const RowHandler& take, LinesByReason& skipped) {
  std::optional<std::int64_t> previous_t;
  TableRow row;
  std::string text;
  for (std::int64_t line = 1; std::getline(in, text); ++line) {
    std::string_view view(text);
    if (line == 1 && view.starts_with("\xEF\xBB\xBF")) view.remove_prefix(3);  // a spreadsheet's UTF-8 mark
    view = trim(view);
    if (view.empty() || view.starts_with('#')) continue;
    row.line = line;
    auto reason = parse_row(split(view, layout.separator), layout, row);
    if (!reason && previous_t && row.t_ns <= *previous_t) reason = "timestamp not after the previous row's";
    if (!reason) reason = take(row);
    if (reason) {
      skipped.add(line, std::move(*reason));
    } else {
      previous_t = row.t_ns;
    }
  }
}

std::optional<std::int64_t> parse_scaled_integer(std::string_view text, int exponent) {
  std::size_t i = 0;
  const bool negative = !text.empty() && text[0] == '-';
  if (!text.empty() && (text[0] == '-' || text[0] == '+')) ++i;
  std::string digits;
  std::optional<std::size_t> point;  // digits before the decimal point
  for (; i < text.size(); ++i) {
    if (std::isdigit(static_cast<unsigned char>(text[i]))) {
      digits += text[i];
    } else if (text[i] == '.' && !point) {
      point = digits.size();
    } else {
      break;
    }
  }
  if (digits.empty()) return std::nullopt;
  long power = 0;
  if (i < text.size() && (text[i] == 'e' || text[i] == 'E')) {
    std::string_view e = text.substr(i + 1);
    if (e.starts_with('+')) e.remove_prefix(1);
    const auto [end, error] = std::from_chars(e.data(), e.data() + e.size(), power);
    if (error != std::errc() || end != e.data() + e.size() || power < -1000 || power > 1000) return std::nullopt;
    i = text.size();
  }
  if (i != text.size()) return std::nullopt;
  const std::size_t lead = digits.find_first_not_of('0');
  if (lead == std::string::npos) return 0;
  // The result's integer part has `k` digits: the significant digits shifted by the point, exponent and unit.
  const long k = static_cast<long>(point.value_or(digits.size())) - static_cast<long>(lead) + power + exponent;
  digits.erase(0, lead);
  if (k > 19) return std::nullopt;
  std::uint64_t value = 0;
  for (long d = 0; d < k; ++d) value = value * 10 + (d < static_cast<long>(digits.size()) ? digits[d] - '0' : 0);
  if (k >= 0 && k < static_cast<long>(digits.size()) && digits[k] >= '5') ++value;
  const std::uint64_t limit = std::uint64_t{std::numeric_limits<std::int64_t>::max()} + (negative ? 1 : 0);
  if (value > limit) return std::nullopt;
  return negative ? static_cast<std::int64_t>(0 - value) : static_cast<std::int64_t>(value);
}

}  // namespace imubridge::replay
