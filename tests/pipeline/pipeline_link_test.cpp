// Bytes -> samples for every wire format, end to end from the simulator's encoder, and the recorder's bookkeeping.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <random>

#include "pipeline/link_decoder.hpp"
#include "pipeline/link_recorder.hpp"
#include "pipeline/mavlink_reference.hpp"
#include "pipeline/recorded_session.hpp"
#include "pipeline/session_config.hpp"
#include "pipeline/session_engine.hpp"
#include "protocol/mavlink_messages.hpp"
#include "sim/frame_encoder.hpp"
#include "sim/scenario.hpp"

namespace imubridge::pipeline {
namespace {

using protocol::WireFormat;

struct Flight {
  std::vector<sim::SimSample> samples;
  std::vector<std::vector<std::uint8_t>> chunks;  // the bytes after each sample (empty while a radio packet fills)
};

Flight fly(WireFormat format, double seconds = 2.0) {
  Flight f;
  f.samples = sim::simulate(sim::make_scenario("paper", 7, seconds));
  sim::FrameEncoder encoder(format);
  for (const auto& s : f.samples) encoder.encode(s, f.chunks.emplace_back());
  encoder.flush(f.chunks.back());
  return f;
}

std::vector<protocol::Sample> decode(WireFormat format, const Flight& f, std::size_t max_piece) {
  LinkDecoder decoder(format, protocol::Calibration::reference_board());
  std::vector<protocol::Sample> out;
  std::mt19937 rng(11);
  std::int64_t t = 0;
  for (const auto& chunk : f.chunks) {
    // Re-cut each chunk at random points, as a serial driver would.
    std::span<const std::uint8_t> rest(chunk);
    while (!rest.empty()) {
      const std::size_t n = std::min<std::size_t>(rest.size(), 1 + rng() % max_piece);
      decoder.feed(rest.first(n), ++t, out);
      rest = rest.subspan(n);
    }
  }
  decoder.finish(++t, out);
  return out;
}

class EveryFormat : public ::testing::TestWithParam<WireFormat> {};

TEST_P(EveryFormat, EverySimulatedSampleArrivesOnceInOrder) {
  const Flight f = fly(GetParam());
  for (std::size_t piece : {1u, 7u, 64u, 4096u}) {
    const auto samples = decode(GetParam(), f, piece);
    ASSERT_EQ(samples.size(), f.samples.size()) << "piece " << piece;
    for (std::size_t i = 0; i < samples.size(); ++i) {
      const auto& got = samples[i];
      const auto& want = f.samples[i];
      // Keyed by the radio on an XBee link; the link's index is the engine's to set.
      const bool xbee = GetParam() == WireFormat::xbee || GetParam() == WireFormat::xbee_escaped;
      EXPECT_EQ(got.source.radio.has_value(), xbee);
      EXPECT_EQ(got.source.link, 0u);
      EXPECT_EQ(got.device_time_us, std::llround(want.time_s * 1e6));
      if (i > 0 && GetParam() == WireFormat::mavlink) {
        // MAVLink numbers every message of a component, so the ATTITUDE messages between IMU samples use some.
        EXPECT_GT(got.seq, samples[i - 1].seq) << "sample " << i;
      } else if (i > 0) {
        EXPECT_EQ(got.seq, samples[i - 1].seq + 1) << "sample " << i;
      }
      for (int a = 0; a < 3; ++a) {
        // imubridge frames carry the board's counts (decoded exactly); MAVLink carries floats.
        const double tolerance =
            GetParam() == WireFormat::mavlink ? 1e-5 * (1 + std::abs(want.measured.accel[a])) : 1e-12;
        EXPECT_NEAR(got.accel[a], want.measured.accel[a], tolerance) << "sample " << i << " axis " << a;
        EXPECT_NEAR(got.gyro[a], want.measured.gyro[a], tolerance) << "sample " << i << " axis " << a;
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Pipeline, EveryFormat,
                         ::testing::Values(WireFormat::imubridge, WireFormat::xbee, WireFormat::xbee_escaped,
                                           WireFormat::mavlink),
                         [](const auto& info) {
                           std::string name(protocol::wire_format_name(info.param));
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name;
                         });

// Two IMUs on one MAVLink link: without a source every IMU message is a sample, the two sensors interleaved; with
// one, only its messages are, and the other's count as frames without a sample.
TEST(LinkDecoder, AMavlinkLinkCanKeepOneImu) {
  namespace mav = protocol::mavlink;
  std::vector<std::uint8_t> bytes;
  std::uint8_t seq = 0;
  for (std::uint32_t i = 0; i < 20; ++i) {
    mav::encode(mav::make_message(mav::HighresImu{.time_usec = 1000 * i, .zacc = -9.8f}, {.seq = seq++}), bytes);
    if (i % 4 == 0) {
      mav::encode(mav::make_message(mav::ScaledImu2{.time_boot_ms = i, .zacc = -500}, {.seq = seq++}), bytes);
    }
  }
  const auto decode = [&](std::optional<mav::ImuSource> source) {
    LinkDecoder decoder(WireFormat::mavlink, protocol::Calibration::reference_board(), source);
    std::vector<protocol::Sample> out;
    decoder.feed(bytes, 1, out);
    decoder.finish(2, out);
    return std::pair(out, decoder.frames_without_sample());
  };
  EXPECT_EQ(decode(std::nullopt).first.size(), 25u);
  const auto [highres, others] = decode(mav::ImuSource{.msgid = 105, .sysid = 1, .compid = 1, .id = 0});
  ASSERT_EQ(highres.size(), 20u);
  EXPECT_EQ(others, 5u);
  for (const auto& s : highres) EXPECT_FLOAT_EQ(s.accel[2], -9.8f);
  const auto [second, _] = decode(mav::ImuSource{.msgid = 116, .sysid = 1, .compid = 1, .id = 0});
  ASSERT_EQ(second.size(), 5u);
  EXPECT_DOUBLE_EQ(second[0].accel[2], -9.80665 / 2);
  EXPECT_TRUE(decode(mav::ImuSource{.msgid = 116, .sysid = 2, .compid = 1, .id = 0}).first.empty());  // another sender
}

// A live link's lock: the first IMU heard that the lock admits, from then on only it; the lock is a function of the
// bytes, so a decoder fed them again (replay) keeps to the same IMU.
TEST(LinkDecoder, AMavlinkLinkLocksOnTheFirstImuItHears) {
  namespace mav = protocol::mavlink;
  std::vector<std::uint8_t> bytes;
  std::uint8_t seq = 0;
  for (std::uint32_t i = 0; i < 20; ++i) {
    if (i % 4 == 0) {
      mav::encode(mav::make_message(mav::ScaledImu2{.time_boot_ms = i, .zacc = -500}, {.seq = seq++}), bytes);
    }
    mav::encode(mav::make_message(mav::HighresImu{.time_usec = 1000 * i, .zacc = -9.8f}, {.seq = seq++}), bytes);
  }
  const auto decode = [&](MavlinkImuLock lock) {
    LinkDecoder decoder(WireFormat::mavlink, protocol::Calibration::reference_board());
    decoder.lock_mavlink_imu(lock);
    EXPECT_FALSE(decoder.mavlink_imu());
    std::vector<protocol::Sample> out;
    decoder.feed(bytes, 1, out);
    decoder.finish(2, out);
    return std::pair(out, decoder.mavlink_imu());
  };
  const auto [first, first_imu] = decode({});
  ASSERT_EQ(first.size(), 5u);  // SCALED_IMU2 came first
  for (const auto& s : first) EXPECT_DOUBLE_EQ(s.accel[2], -9.80665 / 2);
  EXPECT_EQ(first_imu, (mav::ImuSource{.msgid = 116, .sysid = 1, .compid = 1, .id = 0}));
  const auto [highres, highres_imu] = decode({.msgid = 105});
  ASSERT_EQ(highres.size(), 20u);
  for (const auto& s : highres) EXPECT_FLOAT_EQ(s.accel[2], -9.8f);
  EXPECT_EQ(highres_imu, (mav::ImuSource{.msgid = 105, .sysid = 1, .compid = 1, .id = 0}));
  EXPECT_TRUE(decode({.msgid = 105, .id = 1}).first.empty());  // no HIGHRES_IMU with id 1
}

// The reference as frames arrive: a position waits for the first attitude at or after it, then takes the slerp of
// the two around it (at most 0.5 s apart) from ATTITUDE_QUATERNION, which wins over ATTITUDE once sent; the sender is
// the first to send a position (its earlier attitudes kept); other senders are ignored.
TEST(MavlinkReference, PositionsTakeTheSendersAttitudeAroundThem) {
  namespace mav = protocol::mavlink;
  MavlinkReference reference;
  std::vector<store::ReferenceRow> rows;
  const auto feed = [&](const mav::Decoded& d, std::uint8_t sysid, std::int64_t t_ns) {
    reference.on_message(mav::make_message(d, {.sysid = sysid}), t_ns, rows);
  };
  const double s = std::sqrt(0.5);  // yaw 90 degrees: (cos 45, 0, 0, sin 45)
  feed(mav::AttitudeQuaternion{.time_boot_ms = 0, .q1 = 1}, 1, 1);
  feed(mav::Attitude{.time_boot_ms = 0, .yaw = 1.0f}, 1, 1);  // ATTITUDE: not used, the sender sends quaternions
  feed(mav::LocalPositionNed{.time_boot_ms = 50, .x = 5, .vx = 1}, 1, 2);
  feed(mav::LocalPositionNed{.time_boot_ms = 50, .x = 9}, 2, 3);  // another sender
  EXPECT_TRUE(rows.empty()) << "waits for an attitude after it";
  EXPECT_EQ(reference.source(), "LOCAL_POSITION_NED + ATTITUDE_QUATERNION from system 1, component 1");
  feed(mav::AttitudeQuaternion{.time_boot_ms = 100, .q1 = float(s), .q4 = float(s)}, 1, 4);
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_EQ(rows[0].t_ns, 2);
  EXPECT_EQ(rows[0].position[0], 5);
  ASSERT_TRUE(rows[0].velocity);
  EXPECT_EQ((*rows[0].velocity)[0], 1);
  const Eigen::Quaterniond half(Eigen::AngleAxisd(M_PI / 4, Eigen::Vector3d::UnitZ()));
  const Eigen::Quaterniond got(rows[0].quat_wxyz[0], rows[0].quat_wxyz[1], rows[0].quat_wxyz[2], rows[0].quat_wxyz[3]);
  EXPECT_GT(std::abs(got.dot(half)), 1 - 1e-7);
  feed(mav::LocalPositionNed{.time_boot_ms = 100, .x = 6}, 1, 5);  // equal time: that attitude
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_NEAR(rows[1].quat_wxyz[3], s, 1e-7);
  feed(mav::LocalPositionNed{.time_boot_ms = 400, .x = 7}, 1, 6);
  feed(mav::AttitudeQuaternion{.time_boot_ms = 1000, .q1 = 1}, 1, 7);  // 0.9 s after the last: too far
  feed(mav::LocalPositionNed{.time_boot_ms = 1000, .x = 8}, 1, 7);     // equal time again
  feed(mav::LocalPositionNed{.time_boot_ms = 2000, .x = 8}, 1, 8);     // nothing after it
  reference.finish(rows);
  EXPECT_EQ(rows.size(), 3u);
  EXPECT_EQ(reference.rows(), 3u);
  EXPECT_EQ(reference.skipped(), (std::map<std::string, std::uint64_t>{{"no attitude around it", 2}}));
}

TEST(LinkDecoder, UnknownFormatNameIsAClearError) {
  EXPECT_THROW(protocol::parse_wire_format("ubx"), std::invalid_argument);
  EXPECT_EQ(protocol::parse_wire_format("xbee-escaped"), WireFormat::xbee_escaped);
}

class LinkRecorderTest : public ::testing::Test {
 protected:
  std::filesystem::path path_ =
      std::filesystem::temp_directory_path() / ("imubridge_recorder_" + std::to_string(::getpid()) + ".db");
  void TearDown() override {
    for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(path_.string() + suffix);
  }
};

TEST_F(LinkRecorderTest, StoresChunksSamplesAndEveryLossAsEvents) {
  const Flight f = fly(WireFormat::imubridge);
  const std::size_t frame_size = f.chunks[0].size();
  std::vector<std::vector<std::uint8_t>> sent;
  std::size_t samples_sent = 0, garbage = 0;
  for (std::size_t i = 0; i < f.chunks.size(); ++i) {
    if (i == 100 || i == 101 || i == 250) continue;  // three frames lost on the line
    auto chunk = f.chunks[i];
    if (i == 300) {  // a burst of line noise before a frame
      chunk.insert(chunk.begin(), {0x00, 0xB7, 0x13, 0xFF});
      garbage += 4;
    }
    if (i == 320) {
      chunk[frame_size / 2] ^= 0x10;  // a bit flip: that frame fails its CRC
    } else {
      ++samples_sent;
    }
    sent.push_back(std::move(chunk));
  }
  std::int64_t session = 0;
  {
    store::Store store(path_);
    const std::vector<SessionLink> links{
        {.recorded = {.name = "sim", .format = WireFormat::imubridge}, .device = "test"}};
    const RecordedSession recorded =
        begin_recorded_session(store, {.kind = "test", .source = "unit", .started_wall_ns = 1}, links);
    session = recorded.id;
    SessionEngine engine(nullptr);
    engine.add_link(make_decoder(links[0].recorded));
    SessionRecording recording(store, recorded, links, engine);
    engine.add_sink(recording);
    for (std::size_t i = 0; i < sent.size(); ++i) engine.on_chunk(0, sent[i], 1000 * i, 5000 + i);
    engine.finish_link(0, 1000 * sent.size(), 5000 + sent.size());
  }
  store::Store reader(path_, {.read_only = true});
  std::size_t chunk_index = 0;
  reader.for_each_chunk(session, std::nullopt, [&](const store::Chunk& c) {
    ASSERT_LT(chunk_index, sent.size());
    EXPECT_EQ(c.bytes, sent[chunk_index]);
    EXPECT_EQ(c.recv_mono_ns, static_cast<std::int64_t>(1000 * chunk_index));
    ++chunk_index;
  });
  EXPECT_EQ(chunk_index, sent.size());
  std::size_t stored_samples = 0;
  reader.for_each_sample(session, std::nullopt, [&](const protocol::Sample&) { ++stored_samples; });
  EXPECT_EQ(stored_samples, samples_sent);
  std::map<std::string, std::int64_t> totals;
  for (const auto& e : reader.events(session)) totals[e.kind] += e.count;
  EXPECT_EQ(totals["sequence_gap"], 4);  // 100, 101, 250, and the frame that failed its CRC
  EXPECT_EQ(totals["crc_failure"], 1);
  EXPECT_EQ(totals["bytes_discarded"], static_cast<std::int64_t>(garbage + frame_size));
  EXPECT_EQ(totals["counters"], 1);
}

}  // namespace
}  // namespace imubridge::pipeline
