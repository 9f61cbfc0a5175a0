#include "archive/copy_text.hpp"

#include <charconv>
#include <cmath>
#include <limits>

#include "archive/pg_connection.hpp"

namespace imubridge::archive {
namespace {

constexpr char kHex[] = "0123456789abcdef";

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

void CopyRows::separate() {
  if (!first_) data_ += '\t';
  first_ = false;
}

CopyRows& CopyRows::integer(std::int64_t value) {
  separate();
  char text[24];
  const auto result = std::to_chars(text, text + sizeof text, value);
  data_.append(text, result.ptr);
  return *this;
}

CopyRows& CopyRows::real(double value) {
  if (std::isnan(value)) return null();
  separate();
  char text[32];
  // Shortest round trip: PostgreSQL's float8 input reads it back to the same double, -0 and infinities included.
  const auto result = std::to_chars(text, text + sizeof text, value);
  data_.append(text, result.ptr);
  return *this;
}

CopyRows& CopyRows::text(std::string_view value) {
  separate();
  for (char c : value) {
    switch (c) {
      case '\\':
        data_ += "\\\\";
        break;
      case '\t':
        data_ += "\\t";
        break;
      case '\n':
        data_ += "\\n";
        break;
      case '\r':
        data_ += "\\r";
        break;
      default:
        data_ += c;
        break;
    }
  }
  return *this;
}

CopyRows& CopyRows::bytes(std::span<const std::uint8_t> value) {
  separate();
  data_ += "\\\\x";  // bytea's hex form, its backslash escaped for COPY
  for (std::uint8_t b : value) {
    data_ += kHex[b >> 4];
    data_ += kHex[b & 0xF];
  }
  return *this;
}

CopyRows& CopyRows::null() {
  separate();
  data_ += "\\N";
  return *this;
}

void CopyRows::end_row() {
  data_ += '\n';
  ++rows_;
  first_ = true;
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
