#include "archive/copy_format.hpp"

#include <bit>
#include <charconv>
#include <cmath>
#include <limits>

#include "archive/pg_connection.hpp"

namespace imubridge::archive {
namespace {

int hex_digit(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

std::string unescape(std::string_view field) {
  std::string value;
  value.reserve(field.size());
  for (std::size_t i = 0; i < field.size(); ++i) {
    if (field[i] != '\\' || i + 1 == field.size()) {
      value += field[i];
      continue;
    }
    const char c = field[++i];
    switch (c) {
      case 'b':
        value += '\b';
        break;
      case 'f':
        value += '\f';
        break;
      case 'n':
        value += '\n';
        break;
      case 'r':
        value += '\r';
        break;
      case 't':
        value += '\t';
        break;
      case 'v':
        value += '\v';
        break;
      default:
        value += c;
        break;  // \\ and any other escaped character stand for themselves
    }
  }
  return value;
}

}  // namespace

namespace {

template <typename Unsigned>
void append_big_endian(std::string& data, Unsigned value) {
  for (int shift = 8 * static_cast<int>(sizeof(Unsigned)) - 8; shift >= 0; shift -= 8) {
    data += static_cast<char>((value >> shift) & 0xFF);
  }
}

// PGCOPY\n\377\r\n\0, then no flags and no header extension.
constexpr char kBinaryHeader[] = "PGCOPY\n\377\r\n\0\0\0\0\0\0\0\0\0";

}  // namespace

void CopyRows::clear() {
  data_.assign(kBinaryHeader, sizeof kBinaryHeader - 1);
  rows_ = 0;
  fields_ = 0;
  row_start_ = data_.size();
}

void CopyRows::field(std::uint32_t length) {
  if (fields_ == 0) {
    row_start_ = data_.size();
    data_.append(2, '\0');  // the field count, once end_row() knows it
  }
  ++fields_;
  append_big_endian(data_, length);
}

CopyRows& CopyRows::integer(std::int64_t value) {
  field(8);
  append_big_endian(data_, static_cast<std::uint64_t>(value));
  return *this;
}

CopyRows& CopyRows::real(double value) {
  if (std::isnan(value)) return null();
  field(8);
  append_big_endian(data_, std::bit_cast<std::uint64_t>(value));
  return *this;
}

CopyRows& CopyRows::text(std::string_view value) {
  field(static_cast<std::uint32_t>(value.size()));
  data_.append(value);
  return *this;
}

CopyRows& CopyRows::bytes(std::span<const std::uint8_t> value) {
  field(static_cast<std::uint32_t>(value.size()));
  data_.append(reinterpret_cast<const char*>(value.data()), value.size());
  return *this;
}

CopyRows& CopyRows::null() {
  field(0xFFFFFFFF);  // -1: NULL
  return *this;
}

void CopyRows::end_row() {
  data_[row_start_] = static_cast<char>(fields_ >> 8);
  data_[row_start_ + 1] = static_cast<char>(fields_ & 0xFF);
  fields_ = 0;
  ++rows_;
}

std::string_view CopyRows::finish() {
  append_big_endian(data_, std::uint16_t{0xFFFF});  // -1: no more rows
  return data_;
}

CopyLine::CopyLine(std::string_view line) {
  std::size_t start = 0;
  while (true) {
    const std::size_t tab = line.find('\t', start);
    const std::string_view field = line.substr(start, tab == std::string_view::npos ? tab : tab - start);
    if (field == "\\N") {
      fields_.emplace_back(std::nullopt);
    } else {
      fields_.emplace_back(unescape(field));
    }
    if (tab == std::string_view::npos) break;
    start = tab + 1;
  }
}

const std::string& CopyLine::value(std::size_t field) const {
  if (field >= fields_.size()) {
    throw ArchiveError("the archive sent a row of " + std::to_string(fields_.size()) + " fields, expected more");
  }
  if (!fields_[field]) throw ArchiveError("the archive sent NULL where a value is required");
  return *fields_[field];
}

std::int64_t CopyLine::integer(std::size_t field) const {
  const std::string& text = value(field);
  std::int64_t number = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), number);
  if (ec != std::errc() || end != text.data() + text.size()) {
    throw ArchiveError("the archive sent '" + text + "' where an integer was expected");
  }
  return number;
}

std::optional<std::int64_t> CopyLine::optional_integer(std::size_t field) const {
  if (is_null(field)) return std::nullopt;
  return integer(field);
}

double CopyLine::real(std::size_t field) const {
  if (is_null(field)) return std::numeric_limits<double>::quiet_NaN();
  const std::string& text = value(field);
  double number = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), number);
  if (ec != std::errc() || end != text.data() + text.size()) {
    throw ArchiveError("the archive sent '" + text + "' where a number was expected");
  }
  return number;
}

std::string CopyLine::text(std::size_t field) const { return value(field); }

std::vector<std::uint8_t> CopyLine::bytes(std::size_t field) const {
  const std::string& text = value(field);
  if (text.size() < 2 || text[0] != '\\' || text[1] != 'x' || text.size() % 2 != 0) {
    throw ArchiveError("the archive sent a bytea not in hex form (bytea_output must be 'hex')");
  }
  std::vector<std::uint8_t> bytes;
  bytes.reserve(text.size() / 2 - 1);
  for (std::size_t i = 2; i < text.size(); i += 2) {
    const int high = hex_digit(text[i]), low = hex_digit(text[i + 1]);
    if (high < 0 || low < 0) throw ArchiveError("the archive sent a bytea with a non-hex digit");
    bytes.push_back(static_cast<std::uint8_t>(high << 4 | low));
  }
  return bytes;
}

}  // namespace imubridge::archive
