#include "daemon/toml_table.hpp"

#include <algorithm>
#include <sstream>
#include <stdexcept>

#include "estimator/edit_distance.hpp"

namespace imubridge::daemon {
namespace {

using estimator::edit_distance;
using nlohmann::json;

// The known key a typo most likely meant: one containing the other ("baudrate" -> "baud"), else the nearest within
// a third of its length.
std::optional<std::string> closest_key(std::string_view typed, const std::vector<std::string>& known) {
  for (const auto& k : known) {
    if (typed.find(k) != std::string_view::npos || k.find(typed) != std::string::npos) return k;
  }
  std::optional<std::string> best;
  std::size_t best_distance = std::max<std::size_t>(1, typed.size() / 3) + 1;
  for (const auto& k : known) {
    if (const std::size_t d = edit_distance(typed, k); d < best_distance) best = k, best_distance = d;
  }
  return best;
}

}  // namespace

void TomlTable::fail(std::string_view key, const std::string& what) const {
  const toml::node* node = key.empty() ? nullptr : table_.get(key);
  const auto& where = node ? node->source() : table_.source();
  throw std::invalid_argument(std::string(source_) + ":" + std::to_string(where.begin.line) + ": '" + path_of(key) +
                              "' " + what);
}

std::string TomlTable::path_of(std::string_view key) const {
  if (key.empty()) return path_;
  return path_.empty() ? std::string(key) : path_ + "." + std::string(key);
}

const toml::node* TomlTable::find(std::string_view key) {
  known_.emplace_back(key);
  return table_.get(key);
}

std::optional<std::int64_t> TomlTable::integer(std::string_view key, std::int64_t min, std::int64_t max) {
  const toml::node* node = find(key);
  if (!node) return std::nullopt;
  const auto* value = node->as_integer();
  if (!value || value->get() < min || value->get() > max) {
    fail(key, "must be an integer from " + std::to_string(min) + " to " + std::to_string(max));
  }
  return value->get();
}

std::optional<double> TomlTable::number(std::string_view key, double min, double max) {
  const toml::node* node = find(key);
  if (!node) return std::nullopt;
  const std::optional<double> value = node->is_number() ? node->value<double>() : std::nullopt;
  if (!value || !(*value >= min && *value <= max)) {
    std::ostringstream range;
    range << "must be a number from " << min << " to " << max;
    fail(key, range.str());
  }
  return value;
}

std::optional<std::string> TomlTable::string(std::string_view key) {
  const toml::node* node = find(key);
  if (!node) return std::nullopt;
  if (!node->is_string()) fail(key, "must be a string");
  return node->value<std::string>();
}

std::optional<bool> TomlTable::boolean(std::string_view key) {
  const toml::node* node = find(key);
  if (!node) return std::nullopt;
  if (!node->is_boolean()) fail(key, "must be true or false");
  return node->value<bool>();
}

std::optional<TomlTable> TomlTable::table(std::string_view key) {
  const toml::node* node = find(key);
  if (!node) return std::nullopt;
  if (!node->is_table()) fail(key, "must be a table");
  return TomlTable(*node->as_table(), path_of(key), source_);
}

std::vector<std::string> TomlTable::strings(std::string_view key) {
  const toml::node* node = find(key);
  if (!node) return {};
  std::vector<std::string> out;
  const auto* array = node->as_array();
  if (array) {
    for (const auto& v : *array) {
      if (!v.is_string()) break;
      out.push_back(*v.value<std::string>());
    }
  }
  if (!array || out.size() != array->size()) fail(key, "must be an array of strings");
  return out;
}

void TomlTable::finish() const {
  for (const auto& [k, v] : table_) {
    const std::string_view key = k.str();
    if (std::find(known_.begin(), known_.end(), key) != known_.end()) continue;
    std::string message =
        std::string(source_) + ":" + std::to_string(k.source().begin.line) + ": unknown key '" + path_of(key) + "'";
    if (auto guess = closest_key(key, known_)) message += " (did you mean '" + *guess + "'?)";
    throw std::invalid_argument(message);
  }
}

json toml_to_json(const toml::node& node) {
  if (const auto* t = node.as_table()) {
    json j = json::object();
    for (const auto& [k, v] : *t) j[std::string(k.str())] = toml_to_json(v);
    return j;
  }
  if (const auto* a = node.as_array()) {
    json j = json::array();
    for (const auto& v : *a) j.push_back(toml_to_json(v));
    return j;
  }
  if (const auto* i = node.as_integer()) return i->get();
  if (const auto* f = node.as_floating_point()) return f->get();
  if (const auto* b = node.as_boolean()) return b->get();
  if (const auto* s = node.as_string()) return s->get();
  return nullptr;  // dates and times: null fails every check of a value
}

void check_keys(const TomlTable& table, const json& known) {
  TomlTable check = table;
  for (const auto& [key, value] : known.items()) {
    const toml::node* node = check.find(key);
    if (node && value.is_object()) {
      if (!node->is_table()) check.fail(key, "must be a table");
      check_keys(TomlTable(*node->as_table(), check.path_of(key), check.source()), value);
    }
  }
  check.finish();
}

}  // namespace imubridge::daemon
