#pragma once
// A reader of PX4's ULog files, written from the format's specification (PX4 docs, "ULog File Format"): the header,
// the flag bits, the definitions (formats with nested types and padding, info, multi-info, parameters and their
// defaults) and the data section (subscriptions, data, logged strings, sync, dropouts), appended data included.
// The whole file is read into memory: PX4 logs are megabytes, and the importer needs every topic's time series.
#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "importers/import_progress.hpp"

namespace imubridge::importers::ulog {

// Whatever keeps a file from being read at all: not a ULog, a broken header, flag bits or definition. One line.
struct ParseError : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

enum class BaseType { int8, uint8, int16, uint16, int32, uint32, int64, uint64, float32, float64, boolean, character,
                      nested };

struct Field {
  BaseType type = BaseType::uint8;
  std::string type_name;        // "float", or the nested format's name
  std::string name;
  std::size_t array_size = 0;   // 0: a scalar
  std::size_t offset = 0;       // in the record, bytes
  std::size_t size = 0;         // all of it, array included
  bool padding() const { return name.starts_with("_padding"); }
};

struct Format {
  std::string name{};
  std::vector<Field> fields{};
  std::size_t size = 0;          // bytes of a record
  std::size_t trailing_padding = 0;  // bytes of padding at the end, which data messages may leave out
};

// One scalar of a record, nested formats and arrays flattened: "q[0]", "gyro_rad[2]", "esc[3].esc_rpm".
struct Leaf {
  std::string name;
  BaseType type = BaseType::uint8;
  std::size_t offset = 0;
};

// A subscription's records (multi_id tells instances of one topic apart), fixed-size, in file order.
struct Topic {
  std::string name{};
  std::uint8_t multi_id = 0;
  std::vector<Leaf> leaves{};
  std::size_t record_size = 0;
  std::size_t droppable_padding = 0;  // trailing padding bytes, which data messages may leave out
  std::vector<std::uint8_t> data{};  // record_size bytes per record, trailing padding filled with zeros
  std::uint64_t appended_records = 0;  // of them, read from appended data
  // Where the uint64 "timestamp" field lies in a record; set by the reader, looked up by name when not.
  std::optional<std::size_t> timestamp_offset{};

  std::size_t size() const { return record_size == 0 ? 0 : data.size() / record_size; }
  std::optional<std::size_t> leaf(std::string_view name) const;
  double value(std::size_t record, std::size_t leaf) const;
  std::uint64_t timestamp(std::size_t record) const;  // the "timestamp" field, µs; 0 if the format has none
};

struct LoggedString {
  std::uint8_t level = 0;  // syslog's: '0' (emergency) to '7' (debug) in ASCII
  std::optional<std::uint16_t> tag{};  // tagged ('C') strings only
  std::uint64_t timestamp_us = 0;
  std::string text{};
};

struct Dropout {
  std::uint64_t after_us = 0;  // the latest data timestamp before it (leaps over 10 s ahead ignored), µs
  std::uint16_t duration_ms = 0;
};

struct ParamChange {
  std::uint64_t after_us = 0;  // the latest data timestamp before it (leaps over 10 s ahead ignored), µs
  std::string name;
  nlohmann::json value;
};

struct Log {
  std::uint8_t version = 0;
  std::uint64_t start_us = 0;  // the header's timestamp
  std::array<std::uint8_t, 8> compat_flags{}, incompat_flags{};
  std::array<std::uint64_t, 3> appended_offsets{};
  bool data_appended = false;  // incompat flag 0, bit 0
  std::map<std::string, Format> formats;
  std::map<std::string, nlohmann::json> info;        // 'I': name -> value (strings, numbers or arrays of them)
  std::map<std::string, nlohmann::json> multi_info;  // 'M': name -> array of values, continued ones joined
  std::map<std::string, nlohmann::json> params;      // 'P' in the definitions: the values at the start
  std::map<std::string, nlohmann::json> default_params;  // 'Q': {"value", "system", "airframe"}
  std::vector<ParamChange> param_changes;            // 'P' in the data section
  std::vector<Topic> topics;                         // in order of subscription
  std::vector<LoggedString> strings;
  std::vector<Dropout> dropouts;
  std::uint64_t syncs = 0;
  std::uint64_t appended_messages = 0;  // messages read from appended data
  std::map<std::string, std::uint64_t> skipped;  // messages skipped, by reason
  std::optional<std::string> damage;  // why and where reading stopped before the end; everything before it is here

  // The topic's instance, or nothing.
  const Topic* topic(std::string_view name, std::uint8_t multi_id = 0) const;
};

// Throws ParseError when the file is not a ULog or its header, flag bits or definitions are broken. Damage in the
// data section (a truncated last message, a message cut by appended data) stops reading there: Log::damage says so.
// `progress`, when given, hears every kImportProgressEvery messages how far reading is (samples 0).
Log parse(std::span<const std::uint8_t> bytes, const ImportProgressCallback& progress = {});
Log read_file(const std::filesystem::path& path, const ImportProgressCallback& progress = {});

}  // namespace imubridge::importers::ulog
