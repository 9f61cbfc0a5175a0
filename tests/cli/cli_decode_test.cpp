// `imubridge decode` on captures made by the encoders (through `imubridge sim --file`), as a user runs it.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>

#include "tests/support/run_command.hpp"

namespace imubridge::test {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

class DecodeCommand : public ::testing::Test {
 protected:
  fs::path dir_ = fs::temp_directory_path() / ("imubridge_decode_" + std::to_string(::getpid()));
  void SetUp() override { fs::create_directories(dir_); }
  void TearDown() override { fs::remove_all(dir_); }

  fs::path capture(const std::string& protocol, double seconds) {
    const fs::path path = dir_ / (protocol + ".bin");
    const auto r = run_imubridge("sim --scenario paper --seed 3 --duration " + std::to_string(seconds) +
                                 " --protocol " + protocol + " --file " + path.string());
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return path;
  }

  static std::vector<json> lines(const std::string& text) {
    std::vector<json> out;
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);) out.push_back(json::parse(line));
    return out;
  }
};

TEST_F(DecodeCommand, PrintsEveryImubridgeFrameAndCounters) {
  const auto path = capture("imubridge", 1.0);  // 200 samples at 200 Hz
  const auto r = run_imubridge("decode --protocol imubridge " + path.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto frames = lines(r.out);
  ASSERT_EQ(frames.size(), 200u);
  for (std::size_t i = 0; i < frames.size(); ++i) {
    EXPECT_EQ(frames[i]["protocol"], "imubridge");
    EXPECT_EQ(frames[i]["seq"], i);
    EXPECT_EQ(frames[i]["type"], "imu_sample");
    EXPECT_EQ(frames[i]["device_time_us"], i * 5000);
    EXPECT_EQ(frames[i]["accel"].size(), 3u);
  }
  const json counters = json::parse(r.err);
  EXPECT_EQ(counters["imubridge"]["frames_out"], 200);
  EXPECT_EQ(counters["imubridge"]["bytes_in"], fs::file_size(path));
  EXPECT_EQ(counters["imubridge"]["bytes_discarded"], 0);
}

TEST_F(DecodeCommand, XbeePrintsRadioFramesAndTheImuFramesInside) {
  for (const std::string protocol : {"xbee", "xbee-escaped"}) {
    const auto path = capture(protocol, 1.0);
    const auto r = run_imubridge("decode -p " + protocol + " " + path.string());
    ASSERT_EQ(r.exit_code, 0) << r.err;
    int radio = 0, imu = 0;
    for (const auto& j : lines(r.out)) {
      if (j["protocol"] == "xbee") {
        EXPECT_EQ(j["frame_type"], 0x90);
        ++radio;
      } else {
        EXPECT_EQ(j["protocol"], "imubridge");
        EXPECT_EQ(j["source64"], "0013A20040A1B2C3");
        EXPECT_EQ(j["seq"], imu);
        ++imu;
      }
    }
    EXPECT_EQ(imu, 200) << protocol;
    EXPECT_GT(radio, 0) << protocol;
    const json counters = json::parse(r.err);
    EXPECT_EQ(counters["xbee"]["frames_out"], radio);
    EXPECT_EQ(counters["imubridge"]["frames_out"], 200);
  }
}

TEST_F(DecodeCommand, MavlinkPrintsMessageIdsAndDecodedFields) {
  const auto path = capture("mavlink", 1.0);
  const auto r = run_imubridge("decode -p mavlink " + path.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  int highres = 0, attitude = 0;
  for (const auto& j : lines(r.out)) {
    EXPECT_EQ(j["protocol"], "mavlink");
    if (j["msgid"] == 105) {
      EXPECT_EQ(j["name"], "HIGHRES_IMU");
      EXPECT_TRUE(j.contains("xacc"));
      ++highres;
    } else {
      EXPECT_EQ(j["msgid"], 30);
      ++attitude;
    }
  }
  EXPECT_EQ(highres, 200);
  EXPECT_EQ(attitude, 20);
}

TEST_F(DecodeCommand, ReadsStandardInputAndSurvivesGarbageAndTruncation) {
  const auto path = capture("imubridge", 0.5);  // 100 frames of 37 bytes
  std::string bytes = slurp(path);
  const std::string noise = "\x01\x02\xB7\x4D\x09 line noise";
  bytes.insert(37 * 10, noise);
  bytes.resize(bytes.size() - 5);  // the last frame is cut short
  const fs::path damaged = dir_ / "damaged.bin";
  std::ofstream(damaged, std::ios::binary) << bytes;
  const auto r = run_imubridge("decode -p imubridge -", damaged.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(count_lines(r.out), 99);
  const json counters = json::parse(r.err);
  EXPECT_EQ(counters["imubridge"]["frames_out"], 99);
  EXPECT_EQ(counters["imubridge"]["bytes_discarded"], noise.size() + 32);
  EXPECT_EQ(counters["imubridge"]["resyncs"], 2);  // the false sync in the noise, the cut frame at the end
}

TEST_F(DecodeCommand, ClearOneLineErrors) {
  const auto missing = run_imubridge("decode -p imubridge " + (dir_ / "nope.bin").string());
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_EQ(count_lines(missing.err), 1) << missing.err;
  EXPECT_NE(missing.err.find("nope.bin"), std::string::npos);
  const auto bad_protocol = run_imubridge("decode -p ubx -");
  EXPECT_EQ(bad_protocol.exit_code, 2);
  EXPECT_NE(bad_protocol.err.find("ubx"), std::string::npos);
}

}  // namespace
}  // namespace imubridge::test
