#pragma once
// A reader of ArduPilot's DataFlash logs (.bin), written from the format's published description (ArduPilot's
// "Downloading and Analyzing Data Logs" and its log message documentation): records one after another, each the two
// bytes 0xA3 0x95, a message type, then the fields its FMT record gives. FMT (type 0x80, itself defined by the first
// record) names each type, its length (header included), its fields' types (one character each: b B h H i I f d n N
// Z c C e E L M q Q a) and their names; FMTU, UNIT and MULT, where a newer log has them, give each field's unit and
// multiplier. Times are `TimeUS` (µs since boot) in newer logs, `TimeMS` (ms) in older ones.
// The whole file is read into memory: logs are megabytes, and the importer needs whole time series.
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

namespace imubridge::importers::dataflash {

inline constexpr std::uint8_t kHead1 = 0xA3, kHead2 = 0x95, kFmtType = 0x80;
inline constexpr std::size_t kHeaderSize = 3;
inline constexpr std::size_t kFmtLength = 89;  // header, type, length, name[4], format[16], columns[64]

// A file that is not a DataFlash log at all, or cannot be read. One line.
struct ParseError : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

// The bytes of a field of type `c`, or 0 for a character no DataFlash type has.
std::size_t field_size(char type);

struct Field {
  std::string name;
  char type = 'B';
  std::size_t offset = 0;  // in a record's payload (after the 3-byte header)
  // What one count is worth: the format character's own (0.01 for c C e E, 1e-7 for L), replaced by FMTU's
  // multiplier where the log gives one (they describe the same scaling, so it is applied once).
  double scale = 1;
  std::string unit{};  // FMTU's unit label ("m/s", "rad/s", ...), empty when the log has none
  bool text() const { return type == 'n' || type == 'N' || type == 'Z'; }
};

// One message type: its FMT and every record of it, in file order.
struct Message {
  std::uint8_t type = 0;
  std::string name;
  std::size_t length = 0;  // of a record, header included
  std::string format;      // the field types
  std::vector<Field> fields;
  // The field giving each record's time: TimeUS where the message has it, else a leading TimeMS. Unset for messages
  // without one (old PARM, EV): their records take the time of the last timed record before them.
  std::optional<std::size_t> time_field;
  std::vector<std::uint8_t> data;    // length - kHeaderSize bytes per record
  std::vector<std::uint64_t> times;  // each record's time, µs since boot

  std::size_t size() const { return times.size(); }
  std::optional<std::size_t> field(std::string_view name) const;
  // The field's value in its unit: a number scaled, a text field NaN, an `a` array its first element.
  double value(std::size_t record, std::size_t field) const;
  // The field's integer as stored, unscaled (a text field 0).
  std::int64_t integer(std::size_t record, std::size_t field) const;
  // A text field up to its first NUL.
  std::string text(std::size_t record, std::size_t field) const;
};

struct Log {
  std::map<std::uint8_t, Message> messages;  // by type, every type FMT defined (FMT itself included)
  std::uint64_t records = 0;                 // records read, FMT included
  std::map<char, std::string> units;         // UNIT: id -> label
  std::map<char, double> multipliers;        // MULT: id -> multiplier
  std::optional<std::string> damage;  // why and where reading stopped before the end; everything before it is here

  // The message type named `name`, or nothing.
  const Message* message(std::string_view name) const;
};

// Throws ParseError when the file does not begin with a FMT record (it is not a DataFlash log), or that FMT is
// broken. Anything later that cannot be read (a byte where a record's header should be, a type no FMT defined, a
// FMT that is broken or redefines a type otherwise, a record cut short by the end of the file) ends reading there:
// Log::damage says what and at which byte. `progress`, when given, hears every kImportProgressEvery records how far
// reading is (samples 0).
Log parse(std::span<const std::uint8_t> bytes, const ImportProgressCallback& progress = {});
Log read_file(const std::filesystem::path& path, const ImportProgressCallback& progress = {});

}  // namespace imubridge::importers::dataflash
