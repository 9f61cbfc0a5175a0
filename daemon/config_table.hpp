#pragma once
// Tables of configuration keys, after mavlink-router's option_table: one row per TOML key names the key, the member
// it fills and the codec converting between the two. Reading a file and writing a configuration back out
// (config_file.cpp) both walk the same rows, so a key cannot be read without being written, or the reverse; a key is
// added by adding a row.
#include <toml++/toml.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include "daemon/toml_table.hpp"

namespace imubridge::daemon {

// Called for every key when two configurations are compared (compare_keys): the key's path ("link[].baud"), whether
// both hold the same value, and whether the first holds its struct's default.
using KeyVisitor = std::function<void(const std::string& path, bool equal, bool first_is_default)>;

template <typename Struct>
struct ConfigKey {
  std::string_view name;
  std::function<void(TomlTable&, Struct&)> read = {};  // an absent key leaves the member's default
  // write and compare are empty for a key that fills no member (a refused one).
  std::function<void(const Struct&, toml::table&)> write = {};
  std::function<void(const Struct&, const Struct&, const std::string& prefix, const KeyVisitor&)> compare = {};
};
template <typename Struct>
using KeyTable = std::vector<ConfigKey<Struct>>;

// Reads every row in order (which is the order mistakes are found in), then refuses the keys no row names.
template <typename Struct>
void read_keys(TomlTable& table, const KeyTable<Struct>& keys, Struct& out) {
  for (const ConfigKey<Struct>& key : keys) key.read(table, out);
  table.finish();
}

template <typename Struct>
toml::table write_keys(const KeyTable<Struct>& keys, const Struct& in) {
  toml::table out;
  for (const ConfigKey<Struct>& key : keys) {
    if (key.write) key.write(in, out);
  }
  return out;
}

template <typename Struct>
void compare_keys(const KeyTable<Struct>& keys, const Struct& a, const Struct& b, const std::string& prefix,
                  const KeyVisitor& visit) {
  for (const ConfigKey<Struct>& key : keys) {
    if (key.compare) key.compare(a, b, prefix, visit);
  }
}

// What a row may add to reading and writing its member.
template <typename Struct>
struct KeyRules {
  const char* required = nullptr;               // an absent key fails with this, e.g. "needs a 'url' (...)"
  void (*then)(TomlTable&, Struct&) = nullptr;  // after the key is read, present or not: rules across keys
  bool (*written)(const Struct&) = nullptr;     // written only when this holds (an optional member: when set)
};

template <typename T>
inline constexpr bool is_optional_v = false;
template <typename T>
inline constexpr bool is_optional_v<std::optional<T>> = true;

// Compares a member by ==, or through its codec for a table of keys of its own.
template <typename Struct, typename Member, typename Codec>
auto compare_member(std::string_view name, Member Struct::*member, Codec codec) {
  return [=](const Struct& a, const Struct& b, const std::string& prefix, const KeyVisitor& visit) {
    const std::string path = prefix + std::string(name);
    if constexpr (requires { codec.compare(a.*member, b.*member, path, visit); }) {
      codec.compare(a.*member, b.*member, path, visit);
    } else {
      visit(path, a.*member == b.*member, a.*member == Struct{}.*member);
    }
  };
}

// The row of key `name`: `codec` reads a value (std::optional, empty when the key is absent) that goes to `member`,
// and writes the member's value as a TOML value. An optional member is written when it holds a value.
template <typename Struct, typename Member, typename Codec>
ConfigKey<Struct> key(std::string_view name, Member Struct::*member, Codec codec, KeyRules<Struct> rules = {}) {
  ConfigKey<Struct> row{.name = name};
  row.read = [=](TomlTable& table, Struct& out) {
    if (auto value = codec.read(table, name)) {
      out.*member = std::move(*value);
    } else if (rules.required) {
      table.fail("", rules.required);
    }
    if (rules.then) rules.then(table, out);
  };
  row.write = [=](const Struct& in, toml::table& out) {
    if (rules.written && !rules.written(in)) return;
    if constexpr (is_optional_v<Member>) {
      if (in.*member) out.insert(name, codec.write(*(in.*member)));
    } else {
      out.insert(name, codec.write(in.*member));
    }
  };
  row.compare = compare_member(name, member, codec);
  return row;
}

// A key read and written by functions of its own (one spanning two TOML keys, say), compared by its member.
template <typename Struct, typename Member>
ConfigKey<Struct> special_key(std::string_view name, Member Struct::*member, void (*read)(TomlTable&, Struct&),
                              void (*write)(const Struct&, toml::table&)) {
  struct ByEquality {};  // no table of its own: compared with ==
  return {.name = name, .read = read, .write = write, .compare = compare_member(name, member, ByEquality{})};
}

// A key that is never accepted, named so that a typo near it is still recognised: a password, say.
template <typename Struct>
ConfigKey<Struct> refused_key(std::string_view name, const char* why) {
  return {.name = name, .read = [=](TomlTable& table, Struct&) {
            if (table.find(name)) table.fail(name, why);
          }};
}

// Codecs: each reads one TOML value (nullopt when absent, a one-line failure when wrong) and writes one.

template <typename T>
struct Integer {
  std::int64_t min, max;
  std::optional<T> read(TomlTable& table, std::string_view name) const {
    if (auto value = table.integer(name, min, max)) return static_cast<T>(*value);
    return std::nullopt;
  }
  std::int64_t write(T value) const { return static_cast<std::int64_t>(value); }
};

struct Number {
  double min, max;
  std::optional<double> read(TomlTable& table, std::string_view name) const { return table.number(name, min, max); }
  double write(double value) const { return value; }
};

struct Flag {
  std::optional<bool> read(TomlTable& table, std::string_view name) const { return table.boolean(name); }
  bool write(bool value) const { return value; }
};

// A string, or a path.
template <typename T = std::string>
struct Text {
  bool non_empty = false;
  std::optional<T> read(TomlTable& table, std::string_view name) const {
    auto text = table.string(name);
    if (text && non_empty && text->empty()) table.fail(name, "must not be empty");
    if (!text) return std::nullopt;
    return T(std::move(*text));
  }
  std::string write(const T& value) const {
    if constexpr (std::is_same_v<T, std::filesystem::path>) {
      return value.string();
    } else {
      return value;
    }
  }
};

using PathText = Text<std::filesystem::path>;

// A whole number of the duration's unit, as in `interval_s = 30`.
template <typename Duration>
struct WholeDuration {
  std::int64_t min, max;
  std::optional<Duration> read(TomlTable& table, std::string_view name) const {
    if (auto count = table.integer(name, min, max)) return Duration(*count);
    return std::nullopt;
  }
  std::int64_t write(Duration value) const { return static_cast<std::int64_t>(value.count()); }
};

// One of a few names, each standing for a value.
template <typename T>
struct Choice {
  std::vector<std::pair<std::string, T>> options;
  std::optional<T> read(TomlTable& table, std::string_view name) const { return table.choice<T>(name, options); }
  // A value of no option cannot come from a file or the command line; it is written as the first option.
  std::string write(const T& value) const {
    for (const auto& [option, option_value] : options) {
      if (option_value == value) return option;
    }
    return options.front().first;
  }
};

// A sub-table ([store], [link.feedback]) read with rows of its own, starting from `start` when present.
template <typename T>
struct Table {
  KeyTable<T> keys;
  T start{};
  std::optional<T> read(TomlTable& table, std::string_view name) const {
    auto sub = table.table(name);
    if (!sub) return std::nullopt;
    T value = start;
    read_keys(*sub, keys, value);
    return value;
  }
  toml::table write(const T& value) const { return write_keys(keys, value); }
  void compare(const T& a, const T& b, const std::string& path, const KeyVisitor& visit) const {
    compare_keys(keys, a, b, path + ".", visit);
  }
  // Absent from both: its keys are still listed, with their defaults.
  void compare(const std::optional<T>& a, const std::optional<T>& b, const std::string& path,
               const KeyVisitor& visit) const {
    if (a.has_value() != b.has_value()) return visit(path, false, !a.has_value());
    compare(a.value_or(T{}), b.value_or(T{}), path, visit);
  }
};

// An array of tables ([[link]]), each read with the same rows. Written as `name = []` when empty, which it reads.
template <typename T>
struct TableArray {
  KeyTable<T> keys;
  std::optional<std::vector<T>> read(TomlTable& table, std::string_view name) const {
    const toml::node* node = table.find(name);
    if (!node) return std::nullopt;
    const toml::array* array = node->as_array();
    // toml++ does not count an empty array as one of tables.
    if (!array || !(array->empty() || array->is_array_of_tables())) {
      table.fail(name, "must be an array of tables: write [[" + std::string(name) + "]]");
    }
    std::vector<T> values;
    for (std::size_t i = 0; i < array->size(); ++i) {
      TomlTable element(*array->get(i)->as_table(), table.path_of(name) + "[" + std::to_string(i) + "]",
                        table.source());
      read_keys(element, keys, values.emplace_back());
    }
    return values;
  }
  toml::array write(const std::vector<T>& values) const {
    toml::array out;
    for (const T& value : values) out.push_back(write_keys(keys, value));
    return out;
  }
  // Compared element by element; without elements, the keys are listed once with their defaults.
  void compare(const std::vector<T>& a, const std::vector<T>& b, const std::string& path,
               const KeyVisitor& visit) const {
    if (a.size() != b.size()) return visit(path, false, a.empty());
    if (a.empty()) return compare_keys(keys, T{}, T{}, path + "[].", visit);
    for (std::size_t i = 0; i < a.size(); ++i) compare_keys(keys, a[i], b[i], path + "[].", visit);
  }
};

}  // namespace imubridge::daemon
