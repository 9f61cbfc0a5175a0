#include "importers/ulog.hpp"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cstring>
#include <set>
#include <utility>

#include "importers/file_bytes.hpp"

namespace imubridge::importers::ulog {
namespace {

static_assert(std::endian::native == std::endian::little, "ULog is little endian; so is every target imubridge has");

constexpr std::array<std::uint8_t, 7> kMagic{0x55, 0x4c, 0x6f, 0x67, 0x01, 0x12, 0x35};
constexpr std::size_t kHeaderSize = 16;
constexpr std::size_t kMessageHeaderSize = 3;  // uint16 size, uint8 type
constexpr std::array<std::uint8_t, 8> kSyncMagic{0x2f, 0x73, 0x13, 0x20, 0x25, 0x0c, 0xbb, 0x12};
// Nested formats deeper than this are taken for a loop (a format that contains itself).
constexpr int kMaxNesting = 16;
constexpr std::uint64_t kMaxLeapUs = 10'000'000;

template <typename T>
T load(const std::uint8_t* p) {
  T value;
  std::memcpy(&value, p, sizeof value);
  return value;
}

std::optional<std::pair<BaseType, std::size_t>> base_type(std::string_view name) {
  static const std::map<std::string_view, std::pair<BaseType, std::size_t>> kTypes{
      {"int8_t", {BaseType::int8, 1}},     {"uint8_t", {BaseType::uint8, 1}},   {"int16_t", {BaseType::int16, 2}},
      {"uint16_t", {BaseType::uint16, 2}}, {"int32_t", {BaseType::int32, 4}},   {"uint32_t", {BaseType::uint32, 4}},
      {"int64_t", {BaseType::int64, 8}},   {"uint64_t", {BaseType::uint64, 8}}, {"float", {BaseType::float32, 4}},
      {"double", {BaseType::float64, 8}},  {"bool", {BaseType::boolean, 1}},    {"char", {BaseType::character, 1}}};
  const auto it = kTypes.find(name);
  if (it == kTypes.end()) return std::nullopt;
  return it->second;
}

double scalar(BaseType type, const std::uint8_t* p) {
  switch (type) {
    case BaseType::int8: return load<std::int8_t>(p);
    case BaseType::uint8: return load<std::uint8_t>(p);
    case BaseType::int16: return load<std::int16_t>(p);
    case BaseType::uint16: return load<std::uint16_t>(p);
    case BaseType::int32: return load<std::int32_t>(p);
    case BaseType::uint32: return load<std::uint32_t>(p);
    case BaseType::int64: return static_cast<double>(load<std::int64_t>(p));
    case BaseType::uint64: return static_cast<double>(load<std::uint64_t>(p));
    case BaseType::float32: return load<float>(p);
    case BaseType::float64: return load<double>(p);
    case BaseType::boolean: return *p != 0 ? 1 : 0;
    case BaseType::character: return *p;
    case BaseType::nested: return 0;
  }
  return 0;
}

// Text for JSON and the store: nlohmann refuses invalid UTF-8, and logs are written by firmware, so anything but
// printable ASCII (and tabs, newlines) becomes '?'; C strings end at their first NUL.
std::string clean_text(std::string_view text) {
  std::string out;
  for (char c : text) {
    if (c == '\0') break;
    const auto u = static_cast<unsigned char>(c);
    out += (u >= 0x20 && u < 0x7f) || c == '\n' || c == '\t' ? c : '?';
  }
  return out;
}

std::string_view text_of(std::span<const std::uint8_t> bytes) {
  return {reinterpret_cast<const char*>(bytes.data()), bytes.size()};
}

std::string hex_offset(std::size_t offset) { return "byte " + std::to_string(offset); }

// "float[3]" -> ("float", 3); "uint64_t" -> ("uint64_t", 0). Nothing when the brackets are malformed.
std::optional<std::pair<std::string, std::size_t>> split_array(std::string_view type) {
  const auto open = type.find('[');
  if (open == std::string_view::npos) return std::pair{std::string(type), std::size_t{0}};
  if (type.back() != ']' || open == 0) return std::nullopt;
  const std::string_view digits = type.substr(open + 1, type.size() - open - 2);
  std::size_t n = 0;
  const auto [end, error] = std::from_chars(digits.data(), digits.data() + digits.size(), n);
  if (error != std::errc{} || end != digits.data() + digits.size() || n == 0 || n > 65535) return std::nullopt;
  return std::pair{std::string(type.substr(0, open)), n};
}

// A value of 'I', 'M', 'P' or 'Q': its key is "type name".
nlohmann::json decode_value(const std::string& type_text, std::span<const std::uint8_t> bytes) {
  const auto split = split_array(type_text);
  if (!split) return nullptr;
  const auto base = base_type(split->first);
  if (!base) return nullptr;
  if (base->first == BaseType::character) {
    return clean_text(std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
  }
  const std::size_t count = split->second == 0 ? 1 : split->second;
  if (bytes.size() != count * base->second) return nullptr;
  const auto one = [&](std::size_t i) -> nlohmann::json {
    const double v = scalar(base->first, bytes.data() + i * base->second);
    switch (base->first) {
      case BaseType::float32:
      case BaseType::float64: return v;
      case BaseType::boolean: return v != 0;
      case BaseType::int64: return load<std::int64_t>(bytes.data() + i * 8);
      case BaseType::uint64: return load<std::uint64_t>(bytes.data() + i * 8);
      default: return static_cast<std::int64_t>(v);
    }
  };
  if (split->second == 0) return one(0);
  nlohmann::json array = nlohmann::json::array();
  for (std::size_t i = 0; i < count; ++i) array.push_back(one(i));
  return array;
}

// Splits "type name" keys; nothing if there is no space.
std::optional<std::pair<std::string, std::string>> split_key(std::string_view key) {
  const auto space = key.find(' ');
  if (space == std::string_view::npos || space == 0 || space + 1 == key.size()) return std::nullopt;
  return std::pair{std::string(key.substr(0, space)), std::string(key.substr(space + 1))};
}

// "name:type field;type[n] field;..." with the fields' types still unresolved (nested sizes are known later).
Format parse_format(std::string_view text) {
  const auto colon = text.find(':');
  if (colon == std::string_view::npos || colon == 0) {
    throw ParseError("format definition without a name: \"" + clean_text(text.substr(0, 60)) + "\"");
  }
  Format format{.name = clean_text(text.substr(0, colon))};
  std::string_view rest = text.substr(colon + 1);
  while (!rest.empty()) {
    const auto end = rest.find(';');
    const std::string_view item = rest.substr(0, end);
    rest = end == std::string_view::npos ? std::string_view{} : rest.substr(end + 1);
    if (item.empty()) continue;
    const auto key = split_key(item);
    const auto split = key ? split_array(key->first) : std::nullopt;
    if (!split) {
      throw ParseError("format " + format.name + ": malformed field \"" + clean_text(item) + "\"");
    }
    Field field{.type_name = clean_text(split->first), .name = clean_text(key->second), .array_size = split->second};
    if (const auto base = base_type(field.type_name)) {
      field.type = base->first;
      field.size = base->second * std::max<std::size_t>(field.array_size, 1);
    } else {
      field.type = BaseType::nested;
    }
    format.fields.push_back(std::move(field));
  }
  if (format.fields.empty()) throw ParseError("format " + format.name + " has no fields");
  return format;
}

class Reader {
 public:
  Reader(std::span<const std::uint8_t> bytes, const ImportProgressCallback& progress)
      : bytes_(bytes), progress_(progress) {}

  Log read() {
    read_header();
    std::size_t pos = kHeaderSize;
    // The flag bits, if present, come first; logs older than them have none.
    if (bytes_.size() >= pos + kMessageHeaderSize && bytes_[pos + 2] == 'B') pos = read_flag_bits(pos);
    // Sections: the log up to the first appended offset, then each appended part up to the next one.
    std::vector<std::uint64_t> offsets;
    if (log_.data_appended) {
      for (std::uint64_t o : log_.appended_offsets) {
        if (o != 0) offsets.push_back(o);
      }
      std::sort(offsets.begin(), offsets.end());
    }
    std::size_t end = offsets.empty() ? bytes_.size() : std::min<std::uint64_t>(offsets[0], bytes_.size());
    if (!read_messages(pos, end, false)) return finish();
    for (std::size_t i = 0; i < offsets.size(); ++i) {
      if (offsets[i] < pos || offsets[i] > bytes_.size()) {
        log_.damage = "appended data offset " + std::to_string(offsets[i]) + " lies outside the file or before " +
                      hex_offset(pos);
        return finish();
      }
      const std::size_t next = i + 1 < offsets.size() ? std::min<std::uint64_t>(offsets[i + 1], bytes_.size())
                                                      : bytes_.size();
      if (!read_messages(offsets[i], next, true)) return finish();
    }
    return finish();
  }

 private:
  std::span<const std::uint8_t> bytes_;
  const ImportProgressCallback& progress_;
  std::size_t until_progress_ = kImportProgressEvery;
  Log log_;
  std::map<std::uint16_t, std::size_t> subscriptions_;  // msg_id -> index in log_.topics
  bool in_data_ = false;  // past the definitions: the first subscription starts the data section
  std::uint64_t last_timestamp_ = 0;
  std::set<std::string> resolved_;  // formats whose sizes are known

  Log finish() { return std::move(log_); }

  void read_header() {
    if (bytes_.size() < kHeaderSize || !std::equal(kMagic.begin(), kMagic.end(), bytes_.begin())) {
      throw ParseError("not a ULog file (no ULog magic in the first 7 bytes)");
    }
    log_.version = bytes_[7];
    log_.start_us = load<std::uint64_t>(bytes_.data() + 8);
    last_timestamp_ = log_.start_us;
  }

  std::size_t read_flag_bits(std::size_t pos) {
    const std::uint16_t size = load<std::uint16_t>(bytes_.data() + pos);
    if (size < 40 || pos + kMessageHeaderSize + size > bytes_.size()) {
      throw ParseError("flag bits message truncated or too short (" + std::to_string(size) + " bytes)");
    }
    const std::uint8_t* p = bytes_.data() + pos + kMessageHeaderSize;
    std::copy_n(p, 8, log_.compat_flags.begin());
    std::copy_n(p + 8, 8, log_.incompat_flags.begin());
    for (int i = 0; i < 3; ++i) log_.appended_offsets[i] = load<std::uint64_t>(p + 16 + 8 * i);
    log_.data_appended = (log_.incompat_flags[0] & 1) != 0;
    // Incompatible flags this reader does not know mean it cannot read the file correctly, so it must refuse.
    bool unknown = (log_.incompat_flags[0] & ~1u) != 0;
    for (int i = 1; i < 8; ++i) unknown = unknown || log_.incompat_flags[i] != 0;
    if (unknown) throw ParseError("the log sets incompatible flag bits this reader does not know");
    return pos + kMessageHeaderSize + size;
  }

  void skip(const std::string& reason) { ++log_.skipped[reason]; }

  // Reads messages in [pos, end). False when damage stopped it.
  bool read_messages(std::size_t pos, std::size_t end, bool appended) {
    while (pos < end) {
      if (end - pos < kMessageHeaderSize) return damaged(pos, end, "a message header cut short");
      const std::uint16_t size = load<std::uint16_t>(bytes_.data() + pos);
      const char type = static_cast<char>(bytes_[pos + 2]);
      if (end - pos - kMessageHeaderSize < size) return damaged(pos, end, std::string("a '") + clean_text({&type, 1}) +
                                                                              "' message cut short");
      const std::span<const std::uint8_t> body = bytes_.subspan(pos + kMessageHeaderSize, size);
      if (appended) ++log_.appended_messages;
      if (!message(type, body, pos, appended)) return false;
      pos += kMessageHeaderSize + size;
      if (--until_progress_ == 0) {
        until_progress_ = kImportProgressEvery;
        if (progress_) progress_({.bytes_read = pos, .bytes_total = bytes_.size()});
      }
    }
    return true;
  }

  bool damaged(std::size_t pos, std::size_t end, const std::string& what) {
    const std::string where = hex_offset(pos) + (end == bytes_.size() ? " (the file ends)" : " (appended data begins)");
    if (!in_data_) throw ParseError("truncated in the definitions: " + what + " at " + where);
    log_.damage = what + " at " + where;
    return false;
  }

  bool message(char type, std::span<const std::uint8_t> body, std::size_t pos, bool appended) {
    switch (type) {
      case 'F': return format_message(body);
      case 'I':
      case 'P': return info_or_parameter(type, body, pos);
      case 'M':
      case 'Q': return multi_info_or_default(type, body, pos);
      case 'A': return add_subscription(body, pos);
      case 'R': {
        if (body.size() < 2) return malformed(type, pos);
        subscriptions_.erase(load<std::uint16_t>(body.data()));
        return true;
      }
      case 'D': return data(body, appended);
      case 'L':
      case 'C': return logged_string(type, body, pos);
      case 'S': {
        if (body.size() < 8 || !std::equal(kSyncMagic.begin(), kSyncMagic.end(), body.begin())) {
          return malformed(type, pos);
        }
        ++log_.syncs;
        return true;
      }
      case 'O': {
        if (body.size() < 2) return malformed(type, pos);
        log_.dropouts.push_back({last_timestamp_, load<std::uint16_t>(body.data())});
        return true;
      }
      case 'B': skip("flag bits message not first"); return true;
      default: skip("unknown message type"); return true;  // the format allows new types: readers skip them
    }
  }

  // 'F': a format definition.
  bool format_message(std::span<const std::uint8_t> body) {
    Format format = parse_format(text_of(body));
    const std::string name = format.name;
    log_.formats[name] = std::move(format);
    resolved_.clear();
    return true;
  }

  // The name and value of an 'I', 'P', 'M' or 'Q' message: its key ("type name") is as long as body[length_at] says
  // and follows it, the value fills the rest. Nothing when the body is too short or the key malformed.
  static std::optional<std::pair<std::string, nlohmann::json>> read_key_value(std::span<const std::uint8_t> body,
                                                                              std::size_t length_at) {
    const std::size_t from = length_at + 1;
    if (body.size() < from || body.size() < from + body[length_at]) return std::nullopt;
    const auto key = split_key(text_of(body.subspan(from)).substr(0, body[length_at]));
    if (!key) return std::nullopt;
    nlohmann::json value = decode_value(key->first, body.subspan(from + body[length_at]));
    return std::pair{clean_text(key->second), std::move(value)};
  }

  // 'I': an information value; 'P': a parameter, its first value, or one changed in flight.
  bool info_or_parameter(char type, std::span<const std::uint8_t> body, std::size_t pos) {
    auto key_value = read_key_value(body, 0);
    if (!key_value) return malformed(type, pos);
    auto& [name, value] = *key_value;
    if (type == 'I') {
      log_.info[name] = std::move(value);
    } else if (in_data_) {
      log_.param_changes.push_back({last_timestamp_, name, std::move(value)});
    } else {
      log_.params[name] = std::move(value);
    }
    return true;
  }

  // 'M': a multi-message information value, maybe continuing the last; 'Q': a parameter's default.
  bool multi_info_or_default(char type, std::span<const std::uint8_t> body, std::size_t pos) {
    auto key_value = read_key_value(body, 1);
    if (!key_value) return malformed(type, pos);
    auto& [name, value] = *key_value;
    if (type == 'Q') {
      log_.default_params[name] = {
          {"value", std::move(value)}, {"system", (body[0] & 1) != 0}, {"airframe", (body[0] & 2) != 0}};
      return true;
    }
    auto& values = log_.multi_info[name];
    if (!values.is_array()) values = nlohmann::json::array();
    // A continued value is the rest of the previous one (long strings are split over messages).
    if (body[0] != 0 && !values.empty() && values.back().is_string() && value.is_string()) {
      values.back() = values.back().get<std::string>() + value.get<std::string>();
    } else {
      values.push_back(std::move(value));
    }
    return true;
  }

  // 'L': a logged string; 'C': one with a tag.
  bool logged_string(char type, std::span<const std::uint8_t> body, std::size_t pos) {
    const std::size_t header = type == 'L' ? 9 : 11;
    if (body.size() < header) return malformed(type, pos);
    LoggedString s{.level = body[0]};
    if (type == 'C') s.tag = load<std::uint16_t>(body.data() + 1);
    s.timestamp_us = load<std::uint64_t>(body.data() + header - 8);
    s.text = clean_text(text_of(body.subspan(header)));
    log_.strings.push_back(std::move(s));
    return true;
  }

  bool malformed(char type, std::size_t) {
    skip(std::string("malformed '") + clean_text({&type, 1}) + "' message");
    return true;
  }

  // The flattened scalars of `format` at `base`, or a ParseError naming what is undefined or recursive.
  void flatten(const Format& format, const std::string& prefix, std::size_t base, int depth,
               std::vector<Leaf>& leaves) {
    if (depth > kMaxNesting) throw ParseError("format " + format.name + " nests itself");
    for (const Field& field : format.fields) {
      if (field.padding()) continue;
      const std::size_t n = std::max<std::size_t>(field.array_size, 1);
      for (std::size_t i = 0; i < n; ++i) {
        std::string name = prefix + field.name;
        if (field.array_size != 0) name += "[" + std::to_string(i) + "]";
        if (field.type == BaseType::character && field.array_size != 0) {
          if (i == 0) leaves.push_back({prefix + field.name, BaseType::character, base + field.offset});
          continue;  // a string: its first character stands for it
        }
        if (field.type == BaseType::nested) {
          const Format& inner = log_.formats.at(field.type_name);
          flatten(inner, name + ".", base + field.offset + i * inner.size, depth + 1, leaves);
        } else {
          leaves.push_back({std::move(name), field.type, base + field.offset + i * (field.size / n)});
        }
      }
    }
  }

  // Sizes and offsets of `name`'s fields, nested formats first; each format once until formats change.
  Format& resolve(const std::string& name, int depth) {
    const auto it = log_.formats.find(name);
    if (it == log_.formats.end()) throw ParseError("format \"" + name + "\" is used but not defined");
    if (depth > kMaxNesting) throw ParseError("format " + name + " nests itself");
    Format& format = it->second;
    if (resolved_.contains(name)) return format;
    std::size_t offset = 0;
    for (Field& field : format.fields) {
      if (field.type == BaseType::nested) {
        field.size = resolve(field.type_name, depth + 1).size * std::max<std::size_t>(field.array_size, 1);
      }
      field.offset = offset;
      offset += field.size;
      // A record is a data message's body: it never exceeds 64 KiB, and the sums must not overflow.
      if (offset > 65535) throw ParseError("format " + name + " is larger than a message can hold");
    }
    format.size = offset;
    format.trailing_padding = 0;
    for (auto f = format.fields.rbegin(); f != format.fields.rend() && f->padding(); ++f) {
      format.trailing_padding += f->size;
    }
    resolved_.insert(name);
    return format;
  }

  bool add_subscription(std::span<const std::uint8_t> body, std::size_t pos) {
    in_data_ = true;
    if (body.size() < 4) return malformed('A', pos);
    const std::uint8_t multi_id = body[0];
    const std::uint16_t msg_id = load<std::uint16_t>(body.data() + 1);
    const std::string name = clean_text(text_of(body.subspan(3)));
    if (!log_.formats.contains(name)) {
      skip("subscription to an undefined format");
      return true;
    }
    const Format& format = resolve(name, 0);
    Topic topic{.name = name, .multi_id = multi_id, .record_size = format.size,
                .droppable_padding = format.trailing_padding};
    flatten(format, "", 0, 0, topic.leaves);
    if (const auto t = topic.leaf("timestamp"); t && topic.leaves[*t].type == BaseType::uint64) {
      topic.timestamp_offset = topic.leaves[*t].offset;
    }
    // A msg_id reused for the same topic (appended data subscribing again) keeps adding to its records.
    for (std::size_t i = 0; i < log_.topics.size(); ++i) {
      if (log_.topics[i].name == topic.name && log_.topics[i].multi_id == multi_id &&
          log_.topics[i].record_size == topic.record_size) {
        subscriptions_[msg_id] = i;
        return true;
      }
    }
    subscriptions_[msg_id] = log_.topics.size();
    log_.topics.push_back(std::move(topic));
    return true;
  }

  bool data(std::span<const std::uint8_t> body, bool appended) {
    if (body.size() < 2) {
      skip("malformed 'D' message");
      return true;
    }
    const auto it = subscriptions_.find(load<std::uint16_t>(body.data()));
    if (it == subscriptions_.end()) {
      skip("data of an unknown subscription");
      return true;
    }
    Topic& topic = log_.topics[it->second];
    const std::span<const std::uint8_t> record = body.subspan(2);
    if (record.size() + topic.droppable_padding < topic.record_size) {
      skip("data shorter than its format");
      return true;
    }
    const std::size_t n = std::min(record.size(), topic.record_size);
    topic.data.insert(topic.data.end(), record.begin(), record.begin() + static_cast<std::ptrdiff_t>(n));
    topic.data.resize(topic.data.size() + topic.record_size - n, 0);
    if (appended) ++topic.appended_records;
    // The log's clock for dropouts and parameter changes: the latest data timestamp, except one leaping more than
    // kMaxLeapUs ahead (some topics' "timestamp" holds another clock, e.g. mission's in the sample logs).
    const std::uint64_t t = topic.timestamp(topic.size() - 1);
    if (t > last_timestamp_ && t - last_timestamp_ <= kMaxLeapUs) last_timestamp_ = t;
    return true;
  }
};

}  // namespace

std::optional<std::size_t> Topic::leaf(std::string_view name) const {
  for (std::size_t i = 0; i < leaves.size(); ++i) {
    if (leaves[i].name == name) return i;
  }
  return std::nullopt;
}

double Topic::value(std::size_t record, std::size_t leaf) const {
  return scalar(leaves[leaf].type, data.data() + record * record_size + leaves[leaf].offset);
}

std::uint64_t Topic::timestamp(std::size_t record) const {
  if (timestamp_offset) return load<std::uint64_t>(data.data() + record * record_size + *timestamp_offset);
  const auto t = leaf("timestamp");
  if (!t || leaves[*t].type != BaseType::uint64) return 0;
  return load<std::uint64_t>(data.data() + record * record_size + leaves[*t].offset);
}

const Topic* Log::topic(std::string_view name, std::uint8_t multi_id) const {
  for (const Topic& t : topics) {
    if (t.name == name && t.multi_id == multi_id) return &t;
  }
  return nullptr;
}

Log parse(std::span<const std::uint8_t> bytes, const ImportProgressCallback& progress) {
  return Reader(bytes, progress).read();
}

Log read_file(const std::filesystem::path& path, const ImportProgressCallback& progress) {
  const auto bytes = read_file_bytes(path);
  if (!bytes) throw ParseError(path.string() + ": cannot be read");
  try {
    return parse(*bytes, progress);
  } catch (const ParseError& e) {
    throw ParseError(path.string() + ": " + e.what());
  }
}

}  // namespace imubridge::importers::ulog
