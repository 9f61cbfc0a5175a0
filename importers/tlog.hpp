#pragma once
// A reader (and writer) of MAVLink telemetry logs, .tlog, as QGroundControl, Mission Planner and MAVProxy write them:
// records one after another, each an 8-byte big-endian time (µs since the UNIX epoch, when the ground station
// received the frame) and one MAVLink 1 or 2 frame, whose own header gives its length. There is no file header.
// docs/replay.md, "MAVLink telemetry logs".
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace imubridge::importers::tlog {

inline constexpr std::size_t kTimeSize = 8;

// A file that is not a tlog at all, or cannot be read. One line.
struct ParseError : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

struct Record {
  std::uint64_t time_us = 0;  // the ground station's clock, µs since the UNIX epoch
  std::size_t offset = 0;     // of the record (its time's first byte) in the file
  std::size_t size = 0;       // of its frame, which starts at offset + kTimeSize
};

// Bytes that are no record, and where: a record whose bytes are not a MAVLink frame (or whose frame fails its CRC)
// and what follows it up to the next valid record, or the last record cut short by the end of the file.
struct Damage {
  std::size_t offset = 0, bytes = 0;
  std::size_t record = 0;  // how many valid records precede it
  std::string what;        // "not a MAVLink frame", "a frame that fails its CRC", "the last record, cut short ..."
};

struct Log {
  std::vector<std::uint8_t> bytes;  // the file
  std::vector<Record> records;      // every valid record, in file order
  std::vector<Damage> damage;       // in file order
  // Valid frames nothing here can check, kept as they are, by message id: ids in no dialect known here, and MAVLink 1
  // frames of a known id at a length its message cannot have (another dialect's or version's message of that id).
  std::map<std::uint32_t, std::uint64_t> unknown_ids, other_layout_ids;
  std::uint64_t unverified = 0;  // all of them
  // One line for people: "300 frames of message ids no dialect here knows (11042: 300)"; nothing when there are none.
  std::optional<std::string> unverified_summary() const;

  std::span<const std::uint8_t> frame(const Record& r) const {
    return std::span(bytes).subspan(r.offset + kTimeSize, r.size);
  }
  std::size_t damaged_bytes() const;
  // One line for people: "2 damaged stretches, 75 bytes: at byte 1234 (after record 56), 51 bytes: a frame that
  // fails its CRC; ..."; nothing for an undamaged log.
  std::optional<std::string> damage_summary() const;
};

// Reads records from the start. A record that is not an 8-byte time followed by a valid MAVLink frame is damage:
// reading goes on at the next offset where a record with a checked frame starts that is followed by another valid
// record (or the end of the file), the first such whose time is within kResyncWindowUs of the last good record's if
// there is one, so a damaged stretch costs only its own bytes; the last record cut short is damage too. Throws
// ParseError when the file is empty or no valid record starts within its first kSniffBytes: it is not a tlog.
Log parse(std::vector<std::uint8_t> bytes);
// Throws ParseError when the file cannot be read, too.
Log read_file(const std::filesystem::path& path);

inline constexpr std::size_t kSniffBytes = 1024;
inline constexpr std::uint64_t kResyncWindowUs = 600'000'000;  // 10 min

// Appends one record: `time_us` big-endian, then the frame as it is.
void append_record(std::vector<std::uint8_t>& out, std::uint64_t time_us, std::span<const std::uint8_t> frame);

}  // namespace imubridge::importers::tlog
