#include "replay/mcap_writer.hpp"

#include <algorithm>
#include <array>
#include <limits>
#include <stdexcept>

namespace imubridge::replay::mcap {
namespace {

constexpr std::array<std::uint32_t, 256> kCrcTable = [] {
  std::array<std::uint32_t, 256> table{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
    table[i] = c;
  }
  return table;
}();

// Little-endian fields, as every MCAP record is laid out.
class Fields {
 public:
  Fields& u8(std::uint8_t v) { return put(v, 1); }
  Fields& u16(std::uint16_t v) { return put(v, 2); }
  Fields& u32(std::uint32_t v) { return put(v, 4); }
  Fields& u64(std::uint64_t v) { return put(v, 8); }
  Fields& string(std::string_view s) {  // also uint32 length-prefixed Bytes
    u32(length32(s.size()));
    bytes_.append(s);
    return *this;
  }
  Fields& raw(std::string_view s) {
    bytes_.append(s);
    return *this;
  }
  // Map and Array: a uint32 byte length, then the entries.
  Fields& prefixed(const Fields& entries) { return string(entries.bytes_); }
  const std::string& bytes() const { return bytes_; }

 private:
  static std::uint32_t length32(std::size_t n) {
    if (n > std::numeric_limits<std::uint32_t>::max()) throw std::length_error("MCAP field over 4 GiB");
    return static_cast<std::uint32_t>(n);
  }
  Fields& put(std::uint64_t v, int n) {
    for (int i = 0; i < n; ++i) bytes_.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
    return *this;
  }
  std::string bytes_;
};

std::string record(Opcode opcode, std::string_view content) {
  Fields r;
  r.u8(static_cast<std::uint8_t>(opcode)).u64(content.size()).raw(content);
  return r.bytes();
}

}  // namespace

void Crc32::update(std::string_view bytes) {
  for (unsigned char b : bytes) state_ = kCrcTable[(state_ ^ b) & 0xFF] ^ (state_ >> 8);
}

std::uint32_t crc32(std::string_view bytes) {
  Crc32 crc;
  crc.update(bytes);
  return crc.value();
}

Writer::Writer(std::ostream& out, std::string_view library, std::size_t chunk_bytes)
    : out_(out), chunk_bytes_(chunk_bytes) {
  emit(kMagic);
  Fields header;
  header.string("").string(library);  // no well-known profile: JSON messages need none
  emit_record(Opcode::header, header.bytes());
}

std::uint16_t Writer::add_schema(std::string_view name, std::string_view encoding, std::string_view data) {
  const auto id = static_cast<std::uint16_t>(schema_records_.size() + 1);
  Fields schema;
  schema.u16(id).string(name).string(encoding).string(data);
  schema_records_.push_back(schema.bytes());
  emit_record(Opcode::schema, schema.bytes());
  return id;
}

std::uint16_t Writer::add_channel(std::uint16_t schema, std::string_view topic, std::string_view message_encoding,
                                  const std::map<std::string, std::string>& metadata) {
  const auto id = static_cast<std::uint16_t>(channel_records_.size() + 1);
  Fields entries;
  for (const auto& [key, value] : metadata) entries.string(key).string(value);
  Fields channel;
  channel.u16(id).u16(schema).string(topic).string(message_encoding).prefixed(entries);
  channel_records_.push_back(channel.bytes());
  // Before the open chunk, which may hold this channel's messages: a channel precedes its messages in the file.
  emit_record(Opcode::channel, channel.bytes());
  channels_[id];
  return id;
}

void Writer::write(std::uint16_t channel, std::uint64_t log_time, std::string_view data) {
  auto& c = channels_.at(channel);
  Fields message;
  message.u16(channel).u32(c.next_sequence++).u64(log_time).u64(log_time).raw(data);
  if (chunk_messages_.empty()) {
    chunk_start_time_ = chunk_end_time_ = log_time;
  } else {
    chunk_start_time_ = std::min(chunk_start_time_, log_time);
    chunk_end_time_ = std::max(chunk_end_time_, log_time);
  }
  if (message_count_ == 0) start_time_ = end_time_ = log_time;
  start_time_ = std::min(start_time_, log_time);
  end_time_ = std::max(end_time_, log_time);
  chunk_messages_[channel].emplace_back(log_time, chunk_.size());
  chunk_ += record(Opcode::message, message.bytes());
  ++c.count;
  ++message_count_;
  if (chunk_.size() >= chunk_bytes_) close_chunk();
}

void Writer::close_chunk() {
  if (chunk_messages_.empty()) return;
  ChunkIndex index{.start_time = chunk_start_time_,
                   .end_time = chunk_end_time_,
                   .offset = offset_,
                   .length = 0,
                   .message_index_offsets = {},
                   .message_index_length = 0,
                   .records_size = chunk_.size()};
  Fields chunk;
  chunk.u64(chunk_start_time_).u64(chunk_end_time_).u64(chunk_.size()).u32(crc32(chunk_)).string("");
  chunk.u64(chunk_.size()).raw(chunk_);
  emit_record(Opcode::chunk, chunk.bytes());
  index.length = offset_ - index.offset;
  const std::uint64_t indexes_start = offset_;
  for (auto& [channel, entries] : chunk_messages_) {
    // Readers merge channels by time: each index lists its messages in time order, ties in file order.
    std::stable_sort(entries.begin(), entries.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    Fields tuples;
    for (const auto& [time, offset] : entries) tuples.u64(time).u64(offset);
    Fields message_index;
    message_index.u16(channel).prefixed(tuples);
    index.message_index_offsets[channel] = offset_;
    emit_record(Opcode::message_index, message_index.bytes());
  }
  index.message_index_length = offset_ - indexes_start;
  chunk_indexes_.push_back(std::move(index));
  chunk_.clear();
  chunk_messages_.clear();
}

void Writer::finish() {
  if (finished_) throw std::logic_error("MCAP writer finished twice");
  close_chunk();
  Fields data_end;
  data_end.u32(data_crc_.value());  // everything before this record, magic included
  emit_record(Opcode::data_end, data_end.bytes());

  const std::uint64_t summary_start = offset_;
  in_summary_ = true;
  std::vector<std::string> summary_offsets;
  // One group per opcode, each found through its Summary Offset record.
  const auto group = [&](Opcode opcode, const std::vector<std::string>& contents) {
    if (contents.empty()) return;
    const std::uint64_t start = offset_;
    for (const auto& content : contents) emit_record(opcode, content);
    Fields offset;
    offset.u8(static_cast<std::uint8_t>(opcode)).u64(start).u64(offset_ - start);
    summary_offsets.push_back(offset.bytes());
  };
  group(Opcode::schema, schema_records_);
  group(Opcode::channel, channel_records_);
  std::vector<std::string> chunk_indexes;
  for (const auto& c : chunk_indexes_) {
    Fields offsets;
    for (const auto& [channel, offset] : c.message_index_offsets) offsets.u16(channel).u64(offset);
    Fields index;
    index.u64(c.start_time).u64(c.end_time).u64(c.offset).u64(c.length).prefixed(offsets);
    index.u64(c.message_index_length).string("").u64(c.records_size).u64(c.records_size);
    chunk_indexes.push_back(index.bytes());
  }
  group(Opcode::chunk_index, chunk_indexes);
  Fields counts;
  for (const auto& [channel, c] : channels_) counts.u16(channel).u64(c.count);
  Fields statistics;
  statistics.u64(message_count_)
      .u16(static_cast<std::uint16_t>(schema_records_.size()))
      .u32(static_cast<std::uint32_t>(channel_records_.size()))
      .u32(0)  // attachments
      .u32(0)  // metadata
      .u32(static_cast<std::uint32_t>(chunk_indexes_.size()))
      .u64(start_time_)
      .u64(end_time_)
      .prefixed(counts);
  group(Opcode::statistics, {statistics.bytes()});

  const std::uint64_t summary_offset_start = offset_;
  for (const auto& offset : summary_offsets) emit_record(Opcode::summary_offset, offset);
  Fields footer_start;
  footer_start.u8(static_cast<std::uint8_t>(Opcode::footer)).u64(20).u64(summary_start).u64(summary_offset_start);
  emit(footer_start.bytes());
  Fields footer_crc;
  footer_crc.u32(summary_crc_.value());  // from the summary through summary_offset_start
  in_summary_ = false;
  emit(footer_crc.bytes());
  emit(kMagic);
  out_.flush();
  finished_ = true;
}

void Writer::emit(std::string_view bytes) {
  out_.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out_) throw std::runtime_error("write error while writing MCAP");
  offset_ += bytes.size();
  if (in_summary_) {
    summary_crc_.update(bytes);
  } else if (!finished_) {
    data_crc_.update(bytes);
  }
}

void Writer::emit_record(Opcode opcode, std::string_view content) { emit(record(opcode, content)); }

}  // namespace imubridge::replay::mcap
