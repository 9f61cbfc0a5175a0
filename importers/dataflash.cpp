#include "importers/dataflash.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <utility>
#include <variant>

#include "importers/file_bytes.hpp"

namespace imubridge::importers::dataflash {
namespace {

template <typename T>
T load(const std::uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof v);  // DataFlash is little-endian, as every host this builds for
  return v;
}

// A fixed-size text field up to its first NUL.
std::string text_of(const std::uint8_t* p, std::size_t size) {
  std::size_t n = 0;
  while (n < size && p[n] != 0) ++n;
  return std::string(reinterpret_cast<const char*>(p), n);
}

// A float field as an integer: truncated, 0 when NaN or beyond int64 (a cast would be undefined).
std::int64_t to_integer(double v) { return v > -9.2e18 && v < 9.2e18 ? static_cast<std::int64_t>(v) : 0; }

// The scaling a format character itself implies.
double implied_scale(char type) {
  switch (type) {
    case 'c':
    case 'C':
    case 'e':
    case 'E':
      return 0.01;
    case 'L':
      return 1e-7;  // latitude and longitude, degrees
    default:
      return 1;
  }
}

std::vector<std::string> split_columns(const std::string& columns) {
  std::vector<std::string> names;
  if (columns.empty()) return names;
  std::size_t from = 0;
  while (true) {
    const std::size_t comma = columns.find(',', from);
    names.push_back(columns.substr(from, comma - from));
    if (comma == std::string::npos) return names;
    from = comma + 1;
  }
}

std::string hex_byte(std::uint8_t b) {
  static const char* const kDigits = "0123456789abcdef";
  return std::string("0x") + kDigits[b >> 4] + kDigits[b & 15];
}

// A name or type read from the log, as a damage message may show it: one line, whatever bytes a damaged log holds
// (anything outside printable ASCII as \xNN).
std::string printable(std::string_view text) {
  std::string out;
  for (const char c : text) {
    const auto b = static_cast<std::uint8_t>(c);
    if (b >= 0x20 && b < 0x7f && c != '\\') {
      out += c;
    } else {
      out += "\\x" + hex_byte(b).substr(2);
    }
  }
  return out;
}

// The message a FMT record at `p` (kFmtLength bytes) defines, or why it cannot.
std::variant<Message, std::string> read_fmt(const std::uint8_t* p) {
  Message m;
  m.type = p[3];
  m.length = p[4];
  m.name = text_of(p + 5, 4);
  m.format = text_of(p + 9, 16);
  const std::vector<std::string> names = split_columns(text_of(p + 25, 64));
  const std::string what = "a FMT for type " + std::to_string(m.type) + " (" + printable(m.name) + ")";
  // The log's first record defines FMT itself; a FMT for FMT in any other layout cannot be how this log is written.
  if (m.type == kFmtType && (m.length != kFmtLength || m.format != "BBnNZ")) return what + " redefining FMT otherwise";
  if (names.size() != m.format.size()) {
    return what + " with " + std::to_string(m.format.size()) + " field types but " + std::to_string(names.size()) +
           " field names";
  }
  std::size_t offset = 0;
  for (std::size_t i = 0; i < m.format.size(); ++i) {
    const char type = m.format[i];
    const std::size_t size = field_size(type);
    if (size == 0) return what + " with the unknown field type '" + printable(std::string(1, type)) + "'";
    m.fields.push_back({.name = names[i], .type = type, .offset = offset, .scale = implied_scale(type)});
    offset += size;
  }
  if (offset + kHeaderSize != m.length) {
    return what + " whose fields take " + std::to_string(offset + kHeaderSize) + " bytes, not its length " +
           std::to_string(m.length);
  }
  if (const auto us = m.field("TimeUS")) {
    m.time_field = us;
  } else if (!m.fields.empty() && m.fields[0].name == "TimeMS") {
    m.time_field = 0;
  }
  return m;
}

bool same_definition(const Message& a, const Message& b) {
  if (a.name != b.name || a.length != b.length || a.format != b.format || a.fields.size() != b.fields.size()) {
    return false;
  }
  for (std::size_t i = 0; i < a.fields.size(); ++i) {
    if (a.fields[i].name != b.fields[i].name) return false;
  }
  return true;
}

// FMTU's units and multipliers onto the fields they describe.
void apply_units(Log& log) {
  const Message* unit = log.message("UNIT");
  const Message* mult = log.message("MULT");
  const Message* fmtu = log.message("FMTU");
  const auto id_of = [](const Message& m, std::size_t r, std::size_t f) { return static_cast<char>(m.integer(r, f)); };
  if (unit) {
    const auto id = unit->field("Id"), label = unit->field("Label");
    for (std::size_t r = 0; id && label && r < unit->size(); ++r)
      log.units[id_of(*unit, r, *id)] = unit->text(r, *label);
  }
  if (mult) {
    const auto id = mult->field("Id"), value = mult->field("Mult");
    for (std::size_t r = 0; id && value && r < mult->size(); ++r) {
      log.multipliers[id_of(*mult, r, *id)] = mult->value(r, *value);
    }
  }
  if (!fmtu) return;
  const auto type = fmtu->field("FmtType"), units = fmtu->field("UnitIds"), mults = fmtu->field("MultIds");
  if (!type) return;
  for (std::size_t r = 0; r < fmtu->size(); ++r) {
    const auto it = log.messages.find(static_cast<std::uint8_t>(fmtu->integer(r, *type)));
    if (it == log.messages.end()) continue;
    std::vector<Field>& fields = it->second.fields;
    const std::string unit_ids = units ? fmtu->text(r, *units) : "";
    const std::string mult_ids = mults ? fmtu->text(r, *mults) : "";
    for (std::size_t f = 0; f < fields.size(); ++f) {
      if (f < unit_ids.size()) {
        if (const auto u = log.units.find(unit_ids[f]); u != log.units.end()) fields[f].unit = u->second;
      }
      // '-': no multiplier (text, flags); '?': unknown; 0 is ArduPilot's own "no multiplier" value.
      if (f < mult_ids.size() && mult_ids[f] != '-' && mult_ids[f] != '?') {
        const auto m = log.multipliers.find(mult_ids[f]);
        if (m != log.multipliers.end() && std::isfinite(m->second) && m->second != 0) fields[f].scale = m->second;
      }
    }
  }
}

}  // namespace

std::size_t field_size(char type) {
  switch (type) {
    case 'b':
    case 'B':
    case 'M':
      return 1;
    case 'h':
    case 'H':
    case 'c':
    case 'C':
      return 2;
    case 'i':
    case 'I':
    case 'f':
    case 'n':
    case 'e':
    case 'E':
    case 'L':
      return 4;
    case 'd':
    case 'q':
    case 'Q':
      return 8;
    case 'N':
      return 16;
    case 'Z':
    case 'a':
      return 64;
    default:
      return 0;
  }
}

std::optional<std::size_t> Message::field(std::string_view name) const {
  for (std::size_t i = 0; i < fields.size(); ++i) {
    if (fields[i].name == name) return i;
  }
  return std::nullopt;
}

std::int64_t Message::integer(std::size_t record, std::size_t field) const {
  const Field& f = fields[field];
  const std::uint8_t* p = data.data() + record * (length - kHeaderSize) + f.offset;
  switch (f.type) {
    case 'b':
      return load<std::int8_t>(p);
    case 'B':
    case 'M':
      return *p;
    case 'h':
    case 'c':
    case 'a':
      return load<std::int16_t>(p);
    case 'H':
    case 'C':
      return load<std::uint16_t>(p);
    case 'i':
    case 'e':
    case 'L':
      return load<std::int32_t>(p);
    case 'I':
    case 'E':
      return load<std::uint32_t>(p);
    case 'q':
      return load<std::int64_t>(p);
    case 'Q':
      return static_cast<std::int64_t>(load<std::uint64_t>(p));
    case 'f':
      return to_integer(load<float>(p));
    case 'd':
      return to_integer(load<double>(p));
    default:
      return 0;
  }
}

double Message::value(std::size_t record, std::size_t field) const {
  const Field& f = fields[field];
  if (f.text()) return std::numeric_limits<double>::quiet_NaN();
  const std::uint8_t* p = data.data() + record * (length - kHeaderSize) + f.offset;
  double raw = 0;
  if (f.type == 'f') {
    raw = load<float>(p);
  } else if (f.type == 'd') {
    raw = load<double>(p);
  } else if (f.type == 'Q') {
    raw = static_cast<double>(load<std::uint64_t>(p));
  } else {
    raw = static_cast<double>(integer(record, field));
  }
  return raw * f.scale;
}

std::string Message::text(std::size_t record, std::size_t field) const {
  const Field& f = fields[field];
  if (!f.text()) return {};
  return text_of(data.data() + record * (length - kHeaderSize) + f.offset, field_size(f.type));
}

const Message* Log::message(std::string_view name) const {
  for (const auto& [type, m] : messages) {
    if (m.name == name) return &m;
  }
  return nullptr;
}

Log parse(std::span<const std::uint8_t> bytes, const ImportProgressCallback& progress) {
  if (bytes.size() < kFmtLength || bytes[0] != kHead1 || bytes[1] != kHead2 || bytes[2] != kFmtType) {
    throw ParseError("not an ArduPilot DataFlash log: it does not begin with a FMT record (0xA3 0x95 0x80)");
  }
  Log log;
  std::uint64_t last_time_us = 0;
  std::size_t at = 0;
  const auto damage = [&](std::string what) { log.damage = "at byte " + std::to_string(at) + ": " + what; };
  while (at < bytes.size()) {
    const std::size_t left = bytes.size() - at;
    if (left < kHeaderSize) {
      damage("the last record cut short (" + std::to_string(left) + " bytes; the file ends)");
      break;
    }
    if (bytes[at] != kHead1 || bytes[at + 1] != kHead2) {
      damage("no record header (0xA3 0x95) but " + hex_byte(bytes[at]) + " " + hex_byte(bytes[at + 1]));
      break;
    }
    const std::uint8_t type = bytes[at + 2];
    if (type == kFmtType) {
      if (left < kFmtLength) {
        damage("a FMT record cut short (" + std::to_string(left) + " bytes of its " + std::to_string(kFmtLength) +
               "; the file ends)");
        break;
      }
      auto fmt = read_fmt(&bytes[at]);
      if (auto* why = std::get_if<std::string>(&fmt)) {
        if (at == 0) throw ParseError("not a readable DataFlash log: its first record is " + *why);
        damage(*why);
        break;
      }
      // FMT itself (defined by the first record) has no records of its own: FMT records are read here.
      if (Message& defined = std::get<Message>(fmt); defined.type != kFmtType) {
        // try_emplace moves `defined` only when the type is new, so a repeated FMT can be compared with the first.
        const auto [it, added] = log.messages.try_emplace(defined.type, std::move(defined));
        if (!added && !same_definition(it->second, defined)) {
          damage("a FMT redefining type " + std::to_string(it->first) + " (" + printable(it->second.name) +
                 ") otherwise");
          break;
        }
      }
      ++log.records;
      at += kFmtLength;
      continue;
    }
    const auto it = log.messages.find(type);
    if (it == log.messages.end()) {
      damage("a record of type " + std::to_string(type) + ", which no FMT before it defines");
      break;
    }
    Message& m = it->second;
    if (left < m.length) {
      damage("a " + printable(m.name) + " record cut short (" + std::to_string(left) + " bytes of its " +
             std::to_string(m.length) + "; the file ends)");
      break;
    }
    m.data.insert(m.data.end(), bytes.begin() + static_cast<std::ptrdiff_t>(at + kHeaderSize),
                  bytes.begin() + static_cast<std::ptrdiff_t>(at + m.length));
    if (m.time_field) {
      const std::int64_t t = m.integer(m.times.size(), *m.time_field);
      const std::uint64_t unit = m.fields[*m.time_field].name == "TimeUS" ? 1 : 1000;
      last_time_us = static_cast<std::uint64_t>(std::max<std::int64_t>(t, 0)) * unit;
    }
    m.times.push_back(last_time_us);
    at += m.length;
    if (++log.records % kImportProgressEvery == 0 && progress) {
      progress({.bytes_read = at, .bytes_total = bytes.size(), .samples = 0});
    }
  }
  if (progress) progress({.bytes_read = at, .bytes_total = bytes.size(), .samples = 0});
  apply_units(log);
  return log;
}

Log read_file(const std::filesystem::path& path, const ImportProgressCallback& progress) {
  auto bytes = read_file_bytes(path);
  if (!bytes) throw ParseError(path.string() + ": cannot be read");
  try {
    return parse(*bytes, progress);
  } catch (const ParseError& e) {
    throw ParseError(path.string() + ": " + e.what());
  }
}

}  // namespace imubridge::importers::dataflash
