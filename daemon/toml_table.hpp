#pragma once
// Strict reading of TOML tables, for configuration files whose every mistake must be reported as one line naming
// the file, the line and the key: "<source>:<line>: '<path>' <what>", and unknown keys with the key most likely
// meant ("unknown key 'link[0].baudrate' (did you mean 'baud'?)"). Knows nothing of what the keys mean.
#include <toml++/toml.h>

#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace imubridge::daemon {

// One TOML table being read. Every key asked for counts as known, whether present or not; finish() then names the
// first key nobody asked for. Each reader returns nullopt (or nothing) for a key that is absent, and throws
// std::invalid_argument through fail() for one of the wrong type or out of range.
class TomlTable {
 public:
  TomlTable(const toml::table& table, std::string path, std::string_view source)
      : table_(table), path_(std::move(path)), source_(source) {}

  // Throws std::invalid_argument "<source>:<line>: '<path>.<key>' <what>", at the key's line (the table's when the
  // key is empty or absent).
  [[noreturn]] void fail(std::string_view key, const std::string& what) const;
  // "link[0].usb.vid": the key's path from the root of the file.
  std::string path_of(std::string_view key) const;

  // The key's node, or nullptr; either way the key is known from now on.
  const toml::node* find(std::string_view key);

  std::optional<std::int64_t> integer(std::string_view key, std::int64_t min, std::int64_t max);
  std::optional<double> number(std::string_view key, double min, double max);
  std::optional<std::string> string(std::string_view key);
  std::optional<bool> boolean(std::string_view key);
  std::optional<TomlTable> table(std::string_view key);
  std::vector<std::string> strings(std::string_view key);  // an array of strings; empty when absent
  // A string that must be one of `options`' names; the message lists them.
  template <typename Enum>
  std::optional<Enum> choice(std::string_view key, const std::vector<std::pair<std::string, Enum>>& options) {
    const auto text = string(key);
    if (!text) return std::nullopt;
    std::string names;
    for (const auto& [name, value] : options) {
      if (name == *text) return value;
      names += (names.empty() ? "'" : ", '") + name + "'";
    }
    fail(key, "must be one of " + names);
  }

  // Throws for the first key of the table nobody asked for, with the known key it most likely meant.
  void finish() const;

  const toml::table& raw() const { return table_; }
  std::string_view source() const { return source_; }

 private:
  const toml::table& table_;
  std::string path_;
  std::string_view source_;
  std::vector<std::string> known_;
};

// A TOML value as JSON; dates and times, which JSON lacks, as null.
nlohmann::json toml_to_json(const toml::node& node);
// Checks that `table` holds no key `known` (a JSON object of the same layout, such as the defaults) lacks, in
// nested tables too, and that a key `known` holds a table for is a table.
void check_keys(const TomlTable& table, const nlohmann::json& known);

}  // namespace imubridge::daemon
