#pragma once
// PostgreSQL's COPY text format, both ways: rows of tab-separated fields, \N for NULL, backslash escapes, bytea as
// \x and hex. Doubles are written in their shortest form that reads back to the same bits (-0 stays -0), so values
// cross to the archive and back bit for bit, as replay needs.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace imubridge::archive {

// Builds the data of one COPY ... FROM STDIN.
class CopyRows {
 public:
  CopyRows& integer(std::int64_t value);
  CopyRows& real(double value);  // NaN as NULL, as the store keeps it
  CopyRows& text(std::string_view value);
  CopyRows& bytes(std::span<const std::uint8_t> value);
  CopyRows& null();
  void end_row();

  const std::string& data() const noexcept { return data_; }
  std::size_t rows() const noexcept { return rows_; }
  void clear() noexcept {
    data_.clear();
    rows_ = 0;
    first_ = true;
  }

 private:
  void separate();
  std::string data_;
  std::size_t rows_ = 0;
  bool first_ = true;
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
