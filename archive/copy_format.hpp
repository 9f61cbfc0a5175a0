#pragma once
// PostgreSQL's COPY formats: rows go to the archive in the binary format, and come back in the text format
// (tab-separated fields, \N for NULL, backslash escapes, bytea as \x and hex, doubles in their shortest exact form).
// Either way a double keeps its bits (-0 stays -0), so values cross to the archive and back bit for bit, as replay
// needs.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace imubridge::archive {

// Builds the data of one COPY ... FROM STDIN (FORMAT binary): each value as the server keeps it (a double's 8 bytes,
// a text's bytes), so the server only copies them where the text format has it parse every double from its digits:
// a sync takes two thirds of the time (docs/performance.md). The columns must be bigint, double precision, text or
// bytea.
class CopyRows {
 public:
  CopyRows() { clear(); }
  CopyRows& integer(std::int64_t value);  // bigint
  CopyRows& real(double value);           // double precision; NaN as NULL, as the store keeps it
  CopyRows& text(std::string_view value);
  CopyRows& bytes(std::span<const std::uint8_t> value);
  CopyRows& null();
  void end_row();

  std::size_t size() const noexcept { return data_.size(); }
  std::size_t rows() const noexcept { return rows_; }
  // The data to send: the rows and the end marker. Call once, after the last row.
  std::string_view finish();
  void clear();

 private:
  void field(std::uint32_t length);
  std::string data_;
  std::size_t rows_ = 0;
  std::size_t row_start_ = 0;  // where this row's field count goes
  std::uint16_t fields_ = 0;
};

// One line of COPY ... TO STDOUT, its fields unescaped (nullopt: NULL).
class CopyLine {
 public:
  explicit CopyLine(std::string_view line);
  std::size_t size() const noexcept { return fields_.size(); }
  bool is_null(std::size_t field) const { return !fields_.at(field); }
  std::int64_t integer(std::size_t field) const;
  std::optional<std::int64_t> optional_integer(std::size_t field) const;
  double real(std::size_t field) const;  // NULL reads as NaN, as the store's readers do
  std::string text(std::size_t field) const;
  std::vector<std::uint8_t> bytes(std::size_t field) const;  // a bytea

 private:
  const std::string& value(std::size_t field) const;
  std::vector<std::optional<std::string>> fields_;
};

}  // namespace imubridge::archive
