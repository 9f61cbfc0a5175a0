// The MCAP writer's file structure, read back byte by byte as the specification lays it out: magic at both ends,
// the footer's offsets, the summary groups, the chunk and message indexes, and the three CRCs.
#include "replay/mcap_writer.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <map>
#include <sstream>
#include <string>

namespace imubridge::test {
namespace {

using replay::mcap::crc32;
using replay::mcap::kMagic;
using replay::mcap::Opcode;

// Little-endian reads at an offset of the file.
struct Bytes {
  std::string data;
  std::uint64_t u(std::uint64_t at, int n) const {
    if (at + n > data.size()) throw std::out_of_range("read past the end at " + std::to_string(at));
    std::uint64_t v = 0;
    for (int i = 0; i < n; ++i) v |= std::uint64_t(static_cast<unsigned char>(data[at + i])) << (8 * i);
    return v;
  }
  std::uint8_t op(std::uint64_t at) const { return static_cast<std::uint8_t>(u(at, 1)); }
  std::uint64_t record_end(std::uint64_t at) const { return at + 9 + u(at + 1, 8); }
  std::string str(std::uint64_t at) const { return data.substr(at + 4, u(at, 4)); }
};

std::uint8_t op(Opcode o) { return static_cast<std::uint8_t>(o); }

class McapWriterStructure : public ::testing::Test {
 protected:
  // Two channels, 300 messages each, in chunks of about 1 kB: many chunks, each with two message indexes.
  void SetUp() override {
    std::ostringstream out;
    replay::mcap::Writer writer(out, "test", 1024);
    const auto schema = writer.add_schema("s", "jsonschema", R"({"type":"object"})");
    const auto a = writer.add_channel(schema, "/a", "json", {{"k", "v"}});
    const auto b = writer.add_channel(schema, "/b", "json");
    for (int i = 0; i < 300; ++i) {
      writer.write(a, 1000 + 10 * i, R"({"i":)" + std::to_string(i) + "}");
      writer.write(b, 1005 + 10 * i, R"({"j":)" + std::to_string(i) + "}");
    }
    writer.close_chunk();
    writer.write(a, 5, R"({"early":true})");  // out of order: its own chunk
    writer.finish();
    file_.data = out.str();
  }
  Bytes file_;
};

TEST(Crc32, IsTheIsoHdlcCrcOfTheSpecification) {
  EXPECT_EQ(crc32("123456789"), 0xCBF43926u);  // the check value of CRC-32/ISO-HDLC
  EXPECT_EQ(crc32(""), 0u);
}

TEST_F(McapWriterStructure, MagicAtBothEndsAndTheFooterBeforeIt) {
  const auto& d = file_.data;
  ASSERT_GT(d.size(), 2 * kMagic.size() + 29);
  EXPECT_EQ(d.substr(0, 8), kMagic);
  EXPECT_EQ(d.substr(d.size() - 8), kMagic);
  EXPECT_EQ(file_.op(8), op(Opcode::header));
  EXPECT_EQ(file_.str(8 + 9 + 4), "test");  // after the empty profile
  const std::uint64_t footer = d.size() - 8 - 29;
  EXPECT_EQ(file_.op(footer), op(Opcode::footer));
  EXPECT_EQ(file_.u(footer + 1, 8), 20u);
}

TEST_F(McapWriterStructure, DataEndAndSummaryCrcsMatchTheirBytes) {
  const auto& d = file_.data;
  const std::uint64_t footer = d.size() - 8 - 29;
  const std::uint64_t summary_start = file_.u(footer + 9, 8);
  const std::uint64_t summary_offset_start = file_.u(footer + 17, 8);
  ASSERT_GT(summary_start, 0u);
  ASSERT_GT(summary_offset_start, summary_start);
  ASSERT_LT(summary_offset_start, footer);
  // Data End is the record just before the summary, with the CRC of everything before it.
  const std::uint64_t data_end = summary_start - 13;
  ASSERT_EQ(file_.op(data_end), op(Opcode::data_end));
  EXPECT_EQ(file_.u(data_end + 9, 4), crc32(std::string_view(d).substr(0, data_end)));
  // The summary CRC covers the summary, the summary offsets and the footer up to its own field.
  EXPECT_EQ(file_.u(footer + 25, 4), crc32(std::string_view(d).substr(summary_start, footer + 25 - summary_start)));
}

TEST_F(McapWriterStructure, SummaryOffsetsPointAtGroupsOfOneOpcode) {
  const auto& d = file_.data;
  const std::uint64_t footer = d.size() - 8 - 29;
  const std::uint64_t summary_start = file_.u(footer + 9, 8);
  std::map<std::uint8_t, std::pair<std::uint64_t, std::uint64_t>> groups;
  for (std::uint64_t at = file_.u(footer + 17, 8); at < footer; at = file_.record_end(at)) {
    ASSERT_EQ(file_.op(at), op(Opcode::summary_offset));
    groups[file_.op(at + 9)] = {file_.u(at + 10, 8), file_.u(at + 18, 8)};
  }
  for (Opcode o : {Opcode::schema, Opcode::channel, Opcode::chunk_index, Opcode::statistics}) {
    ASSERT_TRUE(groups.count(op(o))) << int(op(o));
  }
  std::uint64_t expected_start = summary_start;  // the groups tile the summary, in the order written
  for (Opcode o : {Opcode::schema, Opcode::channel, Opcode::chunk_index, Opcode::statistics}) {
    const auto [start, length] = groups[op(o)];
    EXPECT_EQ(start, expected_start);
    std::uint64_t at = start;
    for (; at < start + length; at = file_.record_end(at)) EXPECT_EQ(file_.op(at), op(o));
    EXPECT_EQ(at, start + length);
    expected_start = at;
  }
  // Statistics: 601 messages, 1 schema, 2 channels, counts per channel.
  const std::uint64_t stats = groups[op(Opcode::statistics)].first + 9;
  EXPECT_EQ(file_.u(stats, 8), 601u);
  EXPECT_EQ(file_.u(stats + 8, 2), 1u);
  EXPECT_EQ(file_.u(stats + 10, 4), 2u);
  EXPECT_EQ(file_.u(stats + 26, 8), 5u);     // earliest log time
  EXPECT_EQ(file_.u(stats + 34, 8), 3995u);  // latest
  const std::uint64_t counts = stats + 42;
  ASSERT_EQ(file_.u(counts, 4), 2u * 10);
  EXPECT_EQ(file_.u(counts + 4 + 2, 8), 301u);
  EXPECT_EQ(file_.u(counts + 14 + 2, 8), 300u);
}

TEST_F(McapWriterStructure, ChunkIndexesLocateChunksWhoseIndexesLocateTheirMessages) {
  const auto& d = file_.data;
  const std::uint64_t footer = d.size() - 8 - 29;
  std::uint64_t at = file_.u(footer + 9, 8);
  while (file_.op(at) != op(Opcode::chunk_index)) at = file_.record_end(at);
  int chunks = 0;
  std::uint64_t messages = 0;
  for (; file_.op(at) == op(Opcode::chunk_index); at = file_.record_end(at), ++chunks) {
    const std::uint64_t c = at + 9;
    const std::uint64_t start_time = file_.u(c, 8), end_time = file_.u(c + 8, 8);
    const std::uint64_t chunk = file_.u(c + 16, 8), chunk_length = file_.u(c + 24, 8);
    ASSERT_EQ(file_.op(chunk), op(Opcode::chunk));
    EXPECT_EQ(file_.record_end(chunk) - chunk, chunk_length);
    // Chunk: start, end, uncompressed size, CRC, compression "", records.
    EXPECT_EQ(file_.u(chunk + 9, 8), start_time);
    EXPECT_EQ(file_.u(chunk + 17, 8), end_time);
    const std::uint64_t size = file_.u(chunk + 25, 8);
    EXPECT_EQ(file_.u(chunk + 37, 4), 0u);  // no compression
    ASSERT_EQ(file_.u(chunk + 41, 8), size);
    const std::uint64_t records = chunk + 49;
    EXPECT_EQ(file_.u(chunk + 33, 4), crc32(std::string_view(d).substr(records, size)));
    // Message indexes, one per channel, right after the chunk.
    const std::uint64_t offsets = c + 32;
    const std::uint64_t offsets_bytes = file_.u(offsets, 4);
    const std::uint64_t index_length = file_.u(offsets + 4 + offsets_bytes, 8);
    std::uint64_t total = 0;
    for (std::uint64_t e = offsets + 4; e < offsets + 4 + offsets_bytes; e += 10) {
      const std::uint64_t channel = file_.u(e, 2), index = file_.u(e + 2, 8);
      ASSERT_EQ(file_.op(index), op(Opcode::message_index));
      EXPECT_EQ(file_.u(index + 9, 2), channel);
      total += file_.record_end(index) - index;
      const std::uint64_t tuples = index + 11;
      std::uint64_t previous = 0;
      for (std::uint64_t t = tuples + 4; t < tuples + 4 + file_.u(tuples, 4); t += 16, ++messages) {
        const std::uint64_t time = file_.u(t, 8), offset = file_.u(t + 8, 8);
        EXPECT_GE(time, previous);
        previous = time;
        ASSERT_EQ(file_.op(records + offset), op(Opcode::message));
        EXPECT_EQ(file_.u(records + offset + 9, 2), channel);
        EXPECT_EQ(file_.u(records + offset + 15, 8), time);  // log time
        EXPECT_GE(time, start_time);
        EXPECT_LE(time, end_time);
      }
    }
    EXPECT_EQ(total, index_length);
    EXPECT_EQ(file_.record_end(chunk), offsets_bytes ? file_.u(offsets + 6, 8) : 0u);  // indexes follow the chunk
  }
  EXPECT_GT(chunks, 5);
  EXPECT_EQ(messages, 601u);
}

}  // namespace
}  // namespace imubridge::test
