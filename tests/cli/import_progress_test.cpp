// The importers' progress callback (importers/import_progress.hpp) and `imubridge import`'s progress line on a terminal
// (daemon/import_progress_line.hpp): bytes never go back and end at the file's size, samples end at those imported,
// and the line is drawn only where it is shown, at most about ten times a second, and ended with a newline.
#include <gtest/gtest.h>
#include <stdio.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "cli/import_progress_line.hpp"
#include "importers/euroc_import.hpp"
#include "importers/tlog.hpp"
#include "importers/tlog_import.hpp"
#include "importers/ulog.hpp"
#include "importers/ulog_import.hpp"
#include "sim/frame_encoder.hpp"
#include "sim/scenario.hpp"
#include "tests/support/temp_dir.hpp"

namespace imubridge::importers {
namespace {

namespace fs = std::filesystem;

// Every call's progress, checked to be monotonic as it comes.
struct Calls {
  std::vector<ImportProgress> seen;
  ImportProgressCallback callback() {
    return [this](const ImportProgress& p) { seen.push_back(p); };
  }
  // Bytes and samples never decrease, bytes stay within the file, and the last call is the whole file.
  void expect_complete(std::uint64_t file_size, std::uint64_t samples, std::size_t at_least_calls) const {
    ASSERT_GE(seen.size(), at_least_calls);
    for (std::size_t i = 0; i < seen.size(); ++i) {
      EXPECT_EQ(seen[i].bytes_total, file_size) << i;
      EXPECT_LE(seen[i].bytes_read, file_size) << i;
      if (i > 0) {
        EXPECT_GE(seen[i].bytes_read, seen[i - 1].bytes_read) << i;
        EXPECT_GE(seen[i].samples, seen[i - 1].samples) << i;
      }
    }
    EXPECT_LT(seen.front().bytes_read, file_size);  // progress shown before the end, not only at it
    EXPECT_EQ(seen.back().bytes_read, file_size);
    EXPECT_EQ(seen.back().samples, samples);
  }
};

TEST(ImportProgress, UlogBytesWhileParsingThenSamplesEndAtTheFile) {
  test::TempDir dir;
  const fs::path file = fs::path(IMUBRIDGE_SOURCE_DIR) / "tests/data/ulog/sample_log_small.ulg";
  Calls calls;
  store::Store store(dir / "import.db");
  const auto r = import_ulog(store, {.file = file, .progress = calls.callback()});
  calls.expect_complete(fs::file_size(file), r.samples, 3);
  // While parsing, bytes move and there are no samples yet.
  EXPECT_EQ(calls.seen.front().samples, 0u);
  EXPECT_GT(calls.seen.front().bytes_read, 0u);
}

TEST(ImportProgress, TlogRecordsEndAtTheFile) {
  test::TempDir dir;
  std::vector<std::uint8_t> bytes;
  sim::MavlinkTelemetry telemetry;
  std::vector<std::vector<std::uint8_t>> frames;
  sim::simulate(sim::make_scenario("paper", 3, 50.0), [&](const sim::SimSample& s) {  // 10,000 samples
    frames.clear();
    telemetry.encode(s, frames);
    for (const auto& f : frames) {
      tlog::append_record(bytes, 1'704'067'200'000'000 + static_cast<std::uint64_t>(std::llround(s.time_s * 1e6)), f);
    }
  });
  const fs::path file = dir / "flight.tlog";
  std::ofstream(file, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  Calls calls;
  store::Store store(dir / "import.db");
  const auto r = import_tlog(store, {.file = file, .progress = calls.callback()});
  EXPECT_EQ(r.samples, 10'000u);
  calls.expect_complete(bytes.size(), r.samples, 3);
}

TEST(ImportProgress, EurocRowsEndAtTheFile) {
  test::TempDir dir;
  const fs::path csv = dir / "mav0" / "imu0" / "data.csv";
  fs::create_directories(csv.parent_path());
  {
    std::ofstream out(csv);
    out << "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],"
           "a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n";
    for (int i = 0; i < 10'000; ++i) {
      out << 1403636579758560000 + std::int64_t{i} * 5'000'000 << ",0.01,-0.02,0.03,9.81,0.1,-0.2\n";
    }
  }
  Calls calls;
  store::Store store(dir / "import.db");
  const auto r = import_euroc(store, {.dir = dir.path(), .progress = calls.callback()});
  EXPECT_EQ(r.imu.rows, 10'000u);
  calls.expect_complete(fs::file_size(csv), r.imu.rows, 3);
}

// The line as written into a memory stream.
struct Captured {
  char* text = nullptr;
  std::size_t size = 0;
  FILE* out = open_memstream(&text, &size);
  ~Captured() {
    if (out) std::fclose(out);
    std::free(text);
  }
  std::string str() {
    std::fflush(out);
    return std::string(text, size);
  }
};

TEST(ImportProgressLine, FormatsPercentSizeAndSamples) {
  using cli::ImportProgressLine;
  EXPECT_EQ(ImportProgressLine::format("sample.ulg", {1'700'000, 4'053'364, 12'345}),
            "importing sample.ulg  41% 1.7/4.1 MB  12,345 samples");
  EXPECT_EQ(ImportProgressLine::format("f.tlog", {0, 921'631, 0}), "importing f.tlog   0% 0.0/921.6 kB");
  EXPECT_EQ(ImportProgressLine::format("f.tlog", {500, 500, 1}), "importing f.tlog 100% 0.5/0.5 kB  1 sample");
}

TEST(ImportProgressLine, DrawsInPlaceAtMostTenTimesASecondAndEndsWithANewline) {
  Captured c;
  {
    cli::ImportProgressLine line("/data/flight.tlog", c.out, true);
    ASSERT_TRUE(line.callback());
    for (std::uint64_t i = 1; i <= 1000; ++i) line.update({i, 1000, i});  // well within 100 ms
    line.finish();
    line.finish();  // once
  }
  const std::string text = c.str();
  // The first update at once, then none within 100 ms (a loaded machine may let one through), and the final state
  // drawn again before the newline.
  const std::string first = "\r\033[Kimporting flight.tlog   0% 0.0/1.0 kB  1 sample";
  const std::string last = "\r\033[Kimporting flight.tlog 100% 1.0/1.0 kB  1,000 samples\n";
  EXPECT_TRUE(text.starts_with(first)) << text;
  EXPECT_TRUE(text.ends_with(last)) << text;
  EXPECT_LE(std::count(text.begin(), text.end(), '\r'), 4) << text;
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 1) << text;
}

TEST(ImportProgressLine, NothingWhereItIsNotShown) {
  Captured c;
  {
    cli::ImportProgressLine line("flight.tlog", c.out);  // a memory stream is no terminal
    EXPECT_FALSE(line.shown());
    EXPECT_FALSE(line.callback());
    line.update({1, 2, 3});
    line.finish();
  }
  EXPECT_EQ(c.str(), "");
  Captured nothing_reported;
  { cli::ImportProgressLine line("flight.tlog", nothing_reported.out, true); }
  EXPECT_EQ(nothing_reported.str(), "");
}

}  // namespace
}  // namespace imubridge::importers
