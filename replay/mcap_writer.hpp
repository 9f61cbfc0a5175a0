#pragma once
// An MCAP file writer, from the published MCAP format specification (major version 0): the Header, Schema and
// Channel records in the data section, Messages in uncompressed Chunks each followed by one Message Index per
// channel, Data End with the CRC-32 of the data section, then a Summary section (Schemas, Channels, Chunk Indexes,
// Statistics, grouped by opcode), a Summary Offset per group and the Footer with the summary's CRC-32. With the
// index a reader opens a long recording at once and seeks by time or topic without reading every message.
//
// Chunks are not compressed: every MCAP reader opens them without a decompressor, and no compression library is
// needed to build imubridge.
#include <cstdint>
#include <map>
#include <ostream>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace imubridge::replay::mcap {

// The 8 bytes that begin and end every MCAP file.
inline constexpr std::string_view kMagic{"\x89MCAP0\r\n", 8};

enum class Opcode : std::uint8_t {
  header = 0x01,
  footer = 0x02,
  schema = 0x03,
  channel = 0x04,
  message = 0x05,
  chunk = 0x06,
  message_index = 0x07,
  chunk_index = 0x08,
  statistics = 0x0B,
  summary_offset = 0x0E,
  data_end = 0x0F,
};

// CRC-32 as MCAP uses it (ISO-HDLC: reflected polynomial 0xEDB88320, initial and final value 0xFFFFFFFF), fed in
// pieces.
class Crc32 {
 public:
  void update(std::string_view bytes);
  std::uint32_t value() const { return ~state_; }

 private:
  std::uint32_t state_ = 0xFFFFFFFFu;
};
std::uint32_t crc32(std::string_view bytes);

class Writer {
 public:
  // A chunk is closed once its records reach `chunk_bytes`: small enough that a reader seeking to a time reads
  // little, large enough that the index stays small.
  Writer(std::ostream& out, std::string_view library, std::size_t chunk_bytes = 1 << 20);
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;

  // Ids count from 1 (0 means "no schema" in a Channel).
  std::uint16_t add_schema(std::string_view name, std::string_view encoding, std::string_view data);
  std::uint16_t add_channel(std::uint16_t schema, std::string_view topic, std::string_view message_encoding,
                            const std::map<std::string, std::string>& metadata = {});
  // One message; its sequence number counts the channel's messages from 0. Times in nanoseconds.
  void write(std::uint16_t channel, std::uint64_t log_time, std::string_view data);
  // Closes the open chunk, so the next messages start another: between streams far apart in time (one table, then
  // the next), so that each chunk spans a short time and a reader seeking to a time reads few.
  void close_chunk();
  // Closes the last chunk and writes the data end, summary and footer. Nothing may be written after it.
  void finish();

  std::uint64_t messages() const { return message_count_; }

 private:
  struct ChunkIndex {
    std::uint64_t start_time, end_time, offset, length;
    std::map<std::uint16_t, std::uint64_t> message_index_offsets;
    std::uint64_t message_index_length, records_size;
  };
  struct Channel {
    std::uint32_t next_sequence = 0;
    std::uint64_t count = 0;
  };

  // Writes bytes at the end of the file, keeping the offset and the running CRCs.
  void emit(std::string_view bytes);
  void emit_record(Opcode opcode, std::string_view content);

  std::ostream& out_;
  std::size_t chunk_bytes_;
  std::uint64_t offset_ = 0;
  Crc32 data_crc_, summary_crc_;
  bool in_summary_ = false, finished_ = false;
  std::vector<std::string> schema_records_, channel_records_;  // contents, for the summary
  std::map<std::uint16_t, Channel> channels_;
  std::string chunk_;  // the open chunk's records
  std::uint64_t chunk_start_time_ = 0, chunk_end_time_ = 0;
  std::map<std::uint16_t, std::vector<std::pair<std::uint64_t, std::uint64_t>>> chunk_messages_;  // (time, offset)
  std::vector<ChunkIndex> chunk_indexes_;
  std::uint64_t message_count_ = 0, start_time_ = 0, end_time_ = 0;
};

}  // namespace imubridge::replay::mcap
