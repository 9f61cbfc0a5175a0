#include "protocol/decoder_counters.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <nlohmann/json.hpp>

namespace imubridge::protocol {
namespace {

// Every counter a different value, so that a field mixed up with another shows.
constexpr DecoderCounters kSome{.bytes_in = 1,
                                .frames_out = 2,
                                .crc_failures = 3,
                                .resyncs = 4,
                                .bytes_discarded = 5,
                                .sequence_gaps = 6,
                                .frames_lost = 7,
                                .duplicates = 8,
                                .device_restarts = 11,
                                .unsupported = 9,
                                .unverified = 10};

TEST(DecoderCounters, JsonNamesEveryCounter) {
  EXPECT_EQ(nlohmann::json(kSome), nlohmann::json::parse(R"({"bytes_in":1,"frames_out":2,"crc_failures":3,
      "resyncs":4,"bytes_discarded":5,"sequence_gaps":6,"frames_lost":7,"duplicates":8,"device_restarts":11,"unsupported":9,
      "unverified":10})"));
}

TEST(DecoderCounters, AddsEveryCounter) {
  DecoderCounters sum = kSome;
  sum += kSome;
  EXPECT_EQ(sum, (DecoderCounters{.bytes_in = 2,
                                  .frames_out = 4,
                                  .crc_failures = 6,
                                  .resyncs = 8,
                                  .bytes_discarded = 10,
                                  .sequence_gaps = 12,
                                  .frames_lost = 14,
                                  .duplicates = 16,
                                  .device_restarts = 22,
                                  .unsupported = 18,
                                  .unverified = 20}));
}

// What a decoder counted since an earlier reading of its counts: every counter, each its own.
TEST(DecoderCounters, SubtractsAnEarlierReadingFromEveryCounter) {
  DecoderCounters now = kSome;
  now += kSome;
  now += kSome;
  now -= kSome;
  DecoderCounters twice = kSome;
  twice += kSome;
  EXPECT_EQ(now, twice);
  now -= twice;
  EXPECT_EQ(now, DecoderCounters{});
}

TEST(IsRestart, NeedsTheClockBackAndNotTheNextNumber) {
  EXPECT_TRUE(is_restart<std::uint16_t>(5000, 0, 5'000'000, 1'000));        // numbered and timed from zero again
  EXPECT_TRUE(is_restart<std::uint16_t>(3, 0, 9'000'000, 0));               // even when the counter had wrapped
  EXPECT_FALSE(is_restart<std::uint16_t>(65535, 0, 9'000'000, 9'001'000));  // a wrap: the clock goes on
  EXPECT_FALSE(is_restart<std::uint16_t>(41, 42, 9'000'000, 8'000'000));    // the next frame: a clock glitch
  EXPECT_FALSE(is_restart<std::uint16_t>(41, 41, 9'000'000, 8'000'000));    // a repeat
  EXPECT_FALSE(is_restart<std::uint16_t>(41, 60, 9'000'000, 9'100'000));    // a gap
}

TEST(CountSequenceStep, NextGapWrapAndRepeat) {
  DecoderCounters c;
  EXPECT_EQ(count_sequence_step<std::uint8_t>(7, 8, c), 1);
  EXPECT_EQ(count_sequence_step<std::uint8_t>(255, 0, c), 1);  // the wrap is no gap
  EXPECT_EQ(c, DecoderCounters{});

  EXPECT_EQ(count_sequence_step<std::uint8_t>(250, 3, c), 9);  // 251 .. 2 lost, across the wrap
  EXPECT_EQ(count_sequence_step<std::uint16_t>(65535, 4, c), 5);
  EXPECT_EQ(c, (DecoderCounters{.sequence_gaps = 2, .frames_lost = 8 + 4}));

  EXPECT_EQ(count_sequence_step<std::uint16_t>(300, 300, c), 0);  // sent again, not 65535 lost
  EXPECT_EQ(c, (DecoderCounters{.sequence_gaps = 2, .frames_lost = 12, .duplicates = 1}));
}

}  // namespace
}  // namespace imubridge::protocol
