#include "store/store.hpp"

#include <gtest/gtest.h>
#include <signal.h>
#include <sqlite3.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <fstream>
#include <iterator>
#include <limits>
#include <list>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "store/schema.hpp"

namespace imubridge::store {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kDenormal = std::numeric_limits<double>::denorm_min();

std::uint64_t bits(double value) { return std::bit_cast<std::uint64_t>(value); }

// Bit-exact comparison (so -0.0 differs from 0.0), except that any NaN equals any NaN: SQLite keeps no NaN payload.
::testing::AssertionResult same_bits(double expected, double actual) {
  if (bits(expected) == bits(actual) || (std::isnan(expected) && std::isnan(actual))) {
    return ::testing::AssertionSuccess();
  }
  return ::testing::AssertionFailure() << std::hexfloat << expected << " came back as " << actual;
}

template <std::size_t N>
void expect_same_bits(const std::array<double, N>& expected, const std::array<double, N>& actual) {
  for (std::size_t i = 0; i < N; ++i) EXPECT_TRUE(same_bits(expected[i], actual[i])) << "element " << i;
}

void expect_same_sample(const protocol::Sample& expected, const protocol::Sample& actual) {
  EXPECT_EQ(expected.link_id, actual.link_id);
  EXPECT_EQ(expected.seq, actual.seq);
  EXPECT_EQ(expected.device_time_us, actual.device_time_us);
  EXPECT_EQ(expected.recv_mono_ns, actual.recv_mono_ns);
  expect_same_bits(expected.accel, actual.accel);
  expect_same_bits(expected.gyro, actual.gyro);
  ASSERT_EQ(expected.has_mag, actual.has_mag);
  if (expected.has_mag) {
    expect_same_bits(expected.mag, actual.mag);
  }
  ASSERT_EQ(expected.has_temperature, actual.has_temperature);
  if (expected.has_temperature) {
    EXPECT_TRUE(same_bits(expected.temperature_c, actual.temperature_c));
  }
  ASSERT_EQ(expected.has_raw, actual.has_raw);
  if (expected.has_raw) {
    EXPECT_EQ(expected.raw, actual.raw);
  }
}

protocol::Sample sample(std::uint32_t link, std::uint64_t seq) {
  protocol::Sample s;
  s.link_id = link;
  s.seq = seq;
  s.device_time_us = 1000 * static_cast<std::int64_t>(seq);
  s.recv_mono_ns = 5'000'000 + 1'000'000 * static_cast<std::int64_t>(seq);
  s.accel = {0.1 * static_cast<double>(seq), -0.2, -9.80665};
  s.gyro = {0.01, 0.02, -0.03};
  return s;
}

std::vector<char> file_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Queries the file through a connection of its own, independent of the Store under test.
std::string query(const fs::path& path, const char* sql) {
  sqlite3* db = nullptr;
  std::string result = "(cannot open)";
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK) {
    sqlite3_stmt* stmt = nullptr;
    sqlite3_prepare_v2(db, sql, -1, &stmt, nullptr);
    const int rc = sqlite3_step(stmt);
    result = rc == SQLITE_ROW ? reinterpret_cast<const char*>(sqlite3_column_text(stmt, 0)) : sqlite3_errmsg(db);
    sqlite3_finalize(stmt);
  }
  sqlite3_close(db);
  return result;
}

void execute(const fs::path& path, const char* sql) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  EXPECT_EQ(sqlite3_exec(db, sql, nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
  sqlite3_close(db);
}

std::vector<protocol::Sample> samples_of(const Store& store, std::int64_t session) {
  std::vector<protocol::Sample> samples;
  store.for_each_sample(session, std::nullopt, [&](const protocol::Sample& s) { samples.push_back(s); });
  return samples;
}

// The message of the StoreError `action` throws, or "" if it throws none.
template <class Action>
std::string error_of(Action&& action) {
  try {
    action();
  } catch (const StoreError& e) {
    return e.what();
  }
  return "";
}

class StoreTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string pattern = ::testing::TempDir() + "imubridge-store-XXXXXX";
    ASSERT_NE(mkdtemp(pattern.data()), nullptr);
    dir_ = pattern;
    path_ = dir_ / "flight.db";
  }
  void TearDown() override { fs::remove_all(dir_); }

  fs::path dir_;
  fs::path path_;
};

const SessionInfo kLive{.kind = "live",
                        .source = "/dev/ttyUSB0 @ 921600 baud",
                        .config = R"({"links":[{"name":"imu0"}]})",
                        .started_wall_ns = 1'700'000'000'000'000'000};

TEST_F(StoreTest, SessionsLinksRunsAndEventsRoundTrip) {
  SessionInfo sim{.kind = "sim", .source = "sim seed 7", .config = "", .started_wall_ns = 42};
  sim.software_version = "0.0.9";
  std::int64_t live = 0, imu = 0, radio = 0, run = 0;
  std::vector<Event> events;
  {
    Store store(path_);
    live = store.begin_session(kLive);
    imu = store.add_link(live, "imu0", "imubridge", "/dev/ttyUSB0, FTDI A50285BI");
    radio = store.add_link(live, "radio", "xbee", "/dev/ttyUSB1");
    store.end_session(live, kLive.started_wall_ns + 60'000'000'000);
    store.begin_session(sim);
    run = store.begin_run(live, {.kind = "replay", .params_json = R"({"mu":0.3})", .created_wall_ns = 99});
    events = {{.link_id = std::nullopt, .mono_ns = 10, .wall_ns = 20, .kind = "note", .count = 1, .detail = "takeoff"},
              {.link_id = radio, .mono_ns = 11, .wall_ns = 21, .kind = "crc_failure", .count = 3, .detail = ""}};
    for (const Event& event : events) store.append_event(live, event);
  }
  Store store(path_, {.read_only = true});
  const std::vector<Session> sessions = store.sessions();
  ASSERT_EQ(sessions.size(), 2u);
  EXPECT_EQ(sessions[0], (Session{live, kLive, kLive.started_wall_ns + 60'000'000'000, false, this_process()}));
  EXPECT_EQ(sessions[0].info.software_version, IMUBRIDGE_VERSION);
  EXPECT_EQ(sessions[1].info, sim);
  EXPECT_EQ(sessions[1].ended_wall_ns, std::nullopt);
  EXPECT_EQ(store.links(live), (std::vector<Link>{{imu, live, "imu0", "imubridge", "/dev/ttyUSB0, FTDI A50285BI"},
                                                  {radio, live, "radio", "xbee", "/dev/ttyUSB1"}}));
  EXPECT_TRUE(store.links(sessions[1].id).empty());
  EXPECT_EQ(store.runs(live),
            (std::vector<store::Run>{{run, live, {"replay", R"({"mu":0.3})", 99, IMUBRIDGE_VERSION}}}));
  EXPECT_EQ(store.events(live), events);
}

TEST_F(StoreTest, ChunksComeBackByteExactInOrderPerSessionAndPerLink) {
  std::vector<std::uint8_t> every_byte(256);
  for (std::size_t i = 0; i < every_byte.size(); ++i) every_byte[i] = static_cast<std::uint8_t>(i);
  std::vector<Chunk> written;
  std::int64_t session = 0, imu = 0, radio = 0;
  {
    Store store(path_);
    const std::int64_t other_session = store.begin_session(kLive);
    const std::int64_t other_link = store.add_link(other_session, "imu0", "imubridge", "");
    session = store.begin_session(kLive);
    imu = store.add_link(session, "imu0", "imubridge", "");
    radio = store.add_link(session, "radio", "xbee", "");
    written = {{imu, Direction::rx, 100, 1000, every_byte},
               {radio, Direction::tx, 101, 1001, {0x7E, 0x00}},
               {imu, Direction::rx, 102, 1002, {}},  // an empty read is kept: its time is still an observation
               {imu, Direction::rx, 102, 1002, {0x00}},
               {radio, Direction::rx, 99, 999, {0xFF, 0xFE}}};  // stored order wins over timestamps
    for (const Chunk& c : written) {
      store.append_chunk(session, c.link_id, c.direction, c.recv_mono_ns, c.recv_wall_ns, c.bytes);
      store.append_chunk(other_session, other_link, Direction::rx, 0, 0, std::vector<std::uint8_t>{1, 2, 3});
    }
  }
  Store store(path_, {.read_only = true});
  std::vector<Chunk> all, imu_only;
  store.for_each_chunk(session, std::nullopt, [&](const Chunk& c) { all.push_back(c); });
  store.for_each_chunk(session, imu, [&](const Chunk& c) { imu_only.push_back(c); });
  EXPECT_EQ(all, written);
  EXPECT_EQ(imu_only, (std::vector<Chunk>{written[0], written[2], written[3]}));
}

TEST_F(StoreTest, SamplesRoundTripBitExact) {
  std::vector<protocol::Sample> written;
  protocol::Sample plain = sample(0, 0);  // SI values only, as MAVLink HIGHRES_IMU gives them
  written.push_back(plain);
  protocol::Sample full = sample(0, std::numeric_limits<std::uint64_t>::max());  // beyond SQLite's signed range
  full.accel = {-0.0, kDenormal, 1.0 / 3.0};
  full.gyro = {kInf, -kInf, -1e-300};
  full.mag = {-0.0, 21.5, -43.25};
  full.has_mag = true;
  full.temperature_c = -0.0;
  full.has_temperature = true;
  constexpr std::int32_t kLowest = std::numeric_limits<std::int32_t>::min();
  constexpr std::int32_t kHighest = std::numeric_limits<std::int32_t>::max();
  full.raw = {0, -1, kLowest, kHighest, 1, -2, 3, -4, 5, 0x12345678};
  full.has_raw = true;
  written.push_back(full);
  protocol::Sample broken = sample(0, 2);  // a NaN must not lose the row, nor turn into 0
  broken.accel[1] = kNaN;
  broken.mag = {kNaN, 1.0, 2.0};
  broken.has_mag = true;
  written.push_back(broken);

  std::int64_t session = 0;
  {
    Store store(path_);
    session = store.begin_session(kLive);
    for (auto& s : written) s.link_id = store.add_link(session, "imu", "imubridge", "");
    for (const auto& s : written) store.append_sample(session, s);
  }
  const auto read = samples_of(Store(path_, {.read_only = true}), session);
  ASSERT_EQ(read.size(), written.size());
  for (std::size_t i = 0; i < read.size(); ++i) {
    SCOPED_TRACE(i);
    expect_same_sample(written[i], read[i]);
  }
  std::vector<protocol::Sample> one_link;
  Store(path_, {.read_only = true}).for_each_sample(session, written[1].link_id, [&](const protocol::Sample& s) {
    one_link.push_back(s);
  });
  ASSERT_EQ(one_link.size(), 1u);
  EXPECT_EQ(one_link[0].seq, written[1].seq);
}

std::array<double, 7> values(const Estimate& e) { return {e.t_s, e.fx, e.fy, e.vx, e.vy, e.var_vx, e.var_vy}; }

TEST_F(StoreTest, EstimatesAndReferenceRoundTripBitExact) {
  const std::vector<double> awkward = {-0.0, kDenormal, 1.0 / 3.0, -kInf, 6.02214076e23, kNaN, 0.1 + 0.2};
  std::vector<Estimate> estimates;
  for (std::size_t i = 0; i < awkward.size(); ++i) {
    const auto at = [&](std::size_t k) { return awkward[(i + k) % awkward.size()]; };
    estimates.push_back({0, 1000 + i, at(0), at(1), at(2), at(3), at(4), at(5), at(6)});
  }
  const std::vector<ReferenceRow> reference = {
      {.t_ns = 0, .position = {1.0, -0.0, -2.5}, .quat_wxyz = {1, 0, 0, 0}, .velocity = std::nullopt},
      {.t_ns = 5'000'000,
       .position = {1.1, 0.1, -2.5},
       .quat_wxyz = {0.5, -0.5, 0.5, -0.5},
       .velocity = {{0.1, -0.0, kNaN}}}};
  std::int64_t session = 0, run = 0, other_run = 0;
  {
    Store store(path_);
    session = store.begin_session(kLive);
    const std::int64_t link = store.add_link(session, "imu0", "imubridge", "");
    run = store.begin_run(session, {.kind = "live"});
    other_run = store.begin_run(session, {.kind = "replay"});
    for (auto& e : estimates) {
      e.link_id = link;
      store.append_estimate(run, e);
      store.append_estimate(other_run, {.link_id = link, .seq = 7});
    }
    for (const auto& row : reference) store.append_reference(session, row);
  }
  Store store(path_, {.read_only = true});
  std::vector<Estimate> read;
  store.for_each_estimate(run, [&](const Estimate& e) { read.push_back(e); });
  ASSERT_EQ(read.size(), estimates.size());
  for (std::size_t i = 0; i < read.size(); ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(read[i].link_id, estimates[i].link_id);
    EXPECT_EQ(read[i].seq, estimates[i].seq);
    expect_same_bits(values(estimates[i]), values(read[i]));
  }
  std::vector<ReferenceRow> rows;
  store.for_each_reference(session, [&](const ReferenceRow& row) { rows.push_back(row); });
  ASSERT_EQ(rows.size(), reference.size());
  for (std::size_t i = 0; i < rows.size(); ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(rows[i].t_ns, reference[i].t_ns);
    expect_same_bits(reference[i].position, rows[i].position);
    expect_same_bits(reference[i].quat_wxyz, rows[i].quat_wxyz);
    ASSERT_EQ(rows[i].velocity.has_value(), reference[i].velocity.has_value());
    if (rows[i].velocity) {
      expect_same_bits(*reference[i].velocity, *rows[i].velocity);
    }
  }
}

// How many samples a separate reader sees, i.e. how many are committed.
std::string committed_samples(const fs::path& path) { return query(path, "SELECT count(*) FROM samples"); }

TEST_F(StoreTest, BackgroundCheckpointsMoveTheLogIntoTheFileWhileTheRecorderWrites) {
  constexpr std::uint64_t kSamples = 20000;
  {
    Store store(path_, {.background_checkpoint = 20ms});
    const std::int64_t session = store.begin_session(kLive);
    const auto link = store.add_link(session, "imu0", "imubridge", "");
    const auto size_before = fs::file_size(path_);
    for (std::uint64_t i = 0; i < kSamples; ++i) store.append_sample(session, sample(link, i));
    store.commit();
    // SQLite's own checkpoints are off: only the background thread can grow the main file while the store is open.
    const auto deadline = std::chrono::steady_clock::now() + 10s;
    while (fs::file_size(path_) < size_before + 200'000 && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(10ms);
    EXPECT_GT(fs::file_size(path_), size_before + 200'000) << "nothing was checkpointed";
    store.append_sample(session, sample(link, kSamples));  // the writer goes on after a checkpoint
    store.commit();
  }
  EXPECT_EQ(committed_samples(path_), std::to_string(kSamples + 1));
  EXPECT_EQ(query(path_, "PRAGMA integrity_check"), "ok");
}

TEST_F(StoreTest, CommitIfDueWaitsForTheIntervalSinceItsLastCommit) {
  Store store(path_, {.commit_interval = 200ms});
  const std::int64_t session = store.begin_session(kLive);
  const auto link = store.add_link(session, "imu0", "imubridge", "");
  const auto t0 = std::chrono::steady_clock::time_point{} + 1h;

  EXPECT_FALSE(store.commit_if_due(t0)) << "nothing pending";
  store.append_sample(session, sample(link, 0));
  EXPECT_EQ(committed_samples(path_), "0");
  EXPECT_TRUE(store.commit_if_due(t0)) << "the first call has no previous commit to wait for";
  EXPECT_EQ(committed_samples(path_), "1");

  store.append_sample(session, sample(link, 1));
  EXPECT_FALSE(store.commit_if_due(t0 + 199ms));
  EXPECT_EQ(store.pending_rows(), 1u);
  EXPECT_EQ(committed_samples(path_), "1");
  EXPECT_TRUE(store.commit_if_due(t0 + 200ms));
  EXPECT_EQ(store.pending_rows(), 0u);
  EXPECT_EQ(committed_samples(path_), "2");

  EXPECT_FALSE(store.commit_if_due(t0 + 10s)) << "nothing pending";
  store.append_sample(session, sample(link, 2));
  EXPECT_TRUE(store.commit_if_due(t0 + 10s)) << "an idle spell is longer than the interval";
  EXPECT_EQ(committed_samples(path_), "3");
}

TEST_F(StoreTest, BatchLimitExplicitCommitAndDestructionCommit) {
  {
    Store store(path_, {.commit_interval = 1h, .max_batch_rows = 3});
    const std::int64_t session = store.begin_session(kLive);  // committed at once, with its link
    const auto link = store.add_link(session, "imu0", "imubridge", "");
    EXPECT_EQ(query(path_, "SELECT count(*) FROM links"), "1");
    store.append_sample(session, sample(link, 0));
    store.append_sample(session, sample(link, 1));
    EXPECT_EQ(committed_samples(path_), "0");
    store.append_sample(session, sample(link, 2));
    EXPECT_EQ(committed_samples(path_), "3") << "the third row fills the batch";
    store.append_sample(session, sample(link, 3));
    store.commit();
    EXPECT_EQ(committed_samples(path_), "4");
    store.append_sample(session, sample(link, 4));
    EXPECT_EQ(committed_samples(path_), "4");
  }
  EXPECT_EQ(committed_samples(path_), "5") << "destruction commits";
}

TEST_F(StoreTest, RejectedRowThrowsAndLeavesTheBatchAlone) {
  Store store(path_, {.commit_interval = 1h});
  const std::int64_t session = store.begin_session(kLive);
  const auto link = store.add_link(session, "imu0", "imubridge", "");
  const std::int64_t other = store.begin_session(kLive);
  const std::int64_t run = store.begin_run(session, {.kind = "live"});
  store.append_sample(session, sample(link, 0));

  const std::string unknown_link = error_of([&] { store.append_sample(session, sample(link + 100, 1)); });
  EXPECT_EQ(unknown_link, path_.string() + ": FOREIGN KEY constraint failed (appending a sample)");
  EXPECT_NE(error_of([&] { store.append_sample(other, sample(link, 1)); }), "") << "link of another session";
  EXPECT_NE(error_of([&] { store.append_chunk(session, link + 1, Direction::rx, 0, 0, {}); }), "");
  EXPECT_NE(error_of([&] { store.append_event(other + 1, {}); }), "") << "unknown session";
  EXPECT_NE(error_of([&] { store.append_estimate(run + 1, {.link_id = link}); }), "") << "unknown run";
  EXPECT_NE(error_of([&] { store.add_link(other + 1, "imu", "imubridge", ""); }), "");

  EXPECT_EQ(store.pending_rows(), 1u);
  store.append_sample(session, sample(link, 2));
  EXPECT_EQ(error_of([&] { store.end_session(other + 1, 0); }),
            path_.string() + ": no session " + std::to_string(other + 1) + " to end");
  const auto samples = samples_of(store, session);
  ASSERT_EQ(samples.size(), 2u);
  EXPECT_EQ(samples[0].seq, 0u);
  EXPECT_EQ(samples[1].seq, 2u);
}

// Estimates reach SQLite in bursts, kRowsPerStatement to a statement (store.hpp). Whatever the batching, they keep
// their append order across runs and links, count as pending, are seen by their own Store at once and by everyone once
// committed.
std::vector<Estimate> estimates_of(const Store& store, std::int64_t run) {
  std::vector<Estimate> estimates;
  store.for_each_estimate(run, [&](const Estimate& e) { estimates.push_back(e); });
  return estimates;
}

void expect_same_estimates(const std::vector<Estimate>& expected, const std::vector<Estimate>& actual) {
  ASSERT_EQ(expected.size(), actual.size());
  for (std::size_t i = 0; i < expected.size(); ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(expected[i].link_id, actual[i].link_id);
    EXPECT_EQ(expected[i].seq, actual[i].seq);
    expect_same_bits(values(expected[i]), values(actual[i]));
  }
}

// seq of every estimate in id order, as another program reads them.
std::string committed_estimate_seqs(const fs::path& path) {
  return query(path, "SELECT coalesce(group_concat(seq), '') FROM (SELECT seq FROM estimates ORDER BY id)");
}

TEST_F(StoreTest, BatchedEstimatesKeepAppendOrderAndAreSeenAtOnce) {
  Store store(path_, {.commit_interval = 1h});
  const std::int64_t session = store.begin_session(kLive);
  const std::int64_t links[] = {store.add_link(session, "imu0", "imubridge", ""),
                                store.add_link(session, "imu1", "imubridge", ""),
                                store.add_link(session, "imu2", "imubridge", "")};
  const std::int64_t runs[] = {store.begin_run(session, {.kind = "live"}),
                               store.begin_run(session, {.kind = "replay"})};
  const std::size_t count = Store::kMaxWaitingRows + 2 * Store::kRowsPerStatement + 5;  // a burst, then waiting ones
  std::map<std::int64_t, std::vector<Estimate>> appended;
  std::string seqs;
  for (std::size_t i = 0; i < count; ++i) {
    const double x = static_cast<double>(i);
    const Estimate e{.link_id = links[i + 3 < count ? i % 2 : 2],  // a new link's first row after waiting ones
                     .seq = i,
                     .t_s = 0.005 * x,
                     .fx = i == 7 ? -0.0 : 0.1 * x,
                     .fy = i % 5 == 0 ? kNaN : -x,
                     .vx = -1.0 / (x + 1),
                     .vy = kDenormal,
                     .var_vx = kInf,
                     .var_vy = 1e300};
    const std::int64_t run = runs[i % 3 == 0 ? 1 : 0];
    store.append_estimate(run, e);
    appended[run].push_back(e);
    seqs += (seqs.empty() ? "" : ",") + std::to_string(i);
  }
  EXPECT_EQ(store.pending_rows(), count);
  EXPECT_EQ(committed_estimate_seqs(path_), "") << "nothing committed yet";
  for (const std::int64_t run : runs) expect_same_estimates(appended[run], estimates_of(store, run));

  EXPECT_TRUE(store.commit_if_due(std::chrono::steady_clock::now()));
  EXPECT_EQ(store.pending_rows(), 0u);
  EXPECT_EQ(committed_estimate_seqs(path_), seqs);
  const Store reader(path_, {.read_only = true});
  for (const std::int64_t run : runs) expect_same_estimates(appended[run], estimates_of(reader, run));
}

// Chunks and samples wait for their burst too: their own Store's readers see them at once, exactly as it reads them
// back once they are written (a NaN as NULL, an all-NULL group as absent), in append order across bursts and links.
TEST_F(StoreTest, WaitingSamplesAndChunksReadBackAsTheyWillBeStored) {
  Store store(path_, {.commit_interval = 1h});
  const std::int64_t session = store.begin_session(kLive);
  const auto imu0 = store.add_link(session, "imu0", "imubridge", "");
  const auto imu1 = store.add_link(session, "imu1", "imubridge", "");
  const std::size_t count = Store::kMaxWaitingRows + Store::kRowsPerStatement + 3;
  std::vector<protocol::Sample> appended;
  std::vector<Chunk> chunks;
  for (std::size_t i = 0; i < count; ++i) {
    protocol::Sample s = sample(i % 3 == 0 ? imu1 : imu0, i);
    switch (i % 6) {
      case 0:
        s.accel[1] = kNaN, s.gyro[2] = -0.0;
        break;
      case 1:
        s.has_mag = true, s.mag = {kNaN, kNaN, kNaN};
        break;  // all NULL: reads back as no magnetometer
      case 2:
        s.has_mag = true, s.mag = {kNaN, 30.0, kDenormal};
        break;
      case 3:
        s.has_temperature = true, s.temperature_c = kNaN;
        break;
      case 4:
        s.has_temperature = true, s.temperature_c = 21.5, s.has_raw = true, s.raw = {1, -2, 3};
        break;
      case 5:
        s.raw = {7, 7, 7};
        break;  // has_raw is false: the counts are not stored
    }
    store.append_sample(session, s);
    appended.push_back(s);
    const std::vector<std::uint8_t> bytes(i % 4, static_cast<std::uint8_t>(i));
    const Chunk c{.link_id = s.link_id,
                  .direction = i % 5 == 0 ? Direction::tx : Direction::rx,
                  .recv_mono_ns = static_cast<std::int64_t>(i),
                  .recv_wall_ns = -static_cast<std::int64_t>(i),
                  .bytes = bytes};
    store.append_chunk(session, c.link_id, c.direction, c.recv_mono_ns, c.recv_wall_ns, c.bytes);
    chunks.push_back(c);
  }
  EXPECT_EQ(store.pending_rows(), 2 * count);
  EXPECT_EQ(committed_samples(path_), "0");

  const auto read = [&](const Store& from, std::optional<std::int64_t> link) {
    std::vector<protocol::Sample> samples;
    from.for_each_sample(session, link, [&](const protocol::Sample& s) { samples.push_back(s); });
    std::vector<Chunk> read_chunks;
    from.for_each_chunk(session, link, [&](const Chunk& c) { read_chunks.push_back(c); });
    return std::pair{samples, read_chunks};
  };
  const auto [waiting, waiting_chunks] = read(store, std::nullopt);
  const auto [waiting_imu1, waiting_chunks_imu1] = read(store, imu1);
  store.commit();
  EXPECT_EQ(committed_samples(path_), std::to_string(count));
  const Store reader(path_, {.read_only = true});
  const auto [stored, stored_chunks] = read(reader, std::nullopt);
  const auto [stored_imu1, stored_chunks_imu1] = read(reader, imu1);

  ASSERT_EQ(waiting.size(), count);
  ASSERT_EQ(stored.size(), count);
  for (std::size_t i = 0; i < count; ++i) {
    SCOPED_TRACE(i);
    expect_same_sample(stored[i], waiting[i]);
    EXPECT_EQ(stored[i].raw, waiting[i].raw) << "counts not stored read back as zeros";
    EXPECT_EQ(stored[i].seq, appended[i].seq);
  }
  EXPECT_FALSE(stored[1].has_mag);
  EXPECT_TRUE(stored[2].has_mag);
  EXPECT_FALSE(stored[3].has_temperature);
  EXPECT_FALSE(stored[5].has_raw);
  EXPECT_EQ(waiting_chunks, chunks);
  EXPECT_EQ(stored_chunks, chunks);
  ASSERT_EQ(waiting_imu1.size(), stored_imu1.size());
  EXPECT_EQ(waiting_imu1.size(), (count + 2) / 3);
  for (std::size_t i = 0; i < stored_imu1.size(); ++i) expect_same_sample(stored_imu1[i], waiting_imu1[i]);
  EXPECT_EQ(waiting_chunks_imu1, stored_chunks_imu1);
}

TEST_F(StoreTest, EstimateOfAnUnknownLinkFailsAtOnceAndTheWaitingOnesStay) {
  Store store(path_, {.commit_interval = 1h});
  const std::int64_t session = store.begin_session(kLive);
  const std::int64_t link = store.add_link(session, "imu0", "imubridge", "");
  const std::int64_t run = store.begin_run(session, {.kind = "live"});
  for (std::uint64_t seq = 0; seq < 5; ++seq) store.append_estimate(run, {.link_id = link, .seq = seq});

  EXPECT_EQ(error_of([&] { store.append_estimate(run, {.link_id = link + 100, .seq = 5}); }),
            path_.string() + ": FOREIGN KEY constraint failed (appending an estimate)");
  store.append_estimate(run, {.link_id = link, .seq = 6});
  EXPECT_EQ(store.pending_rows(), 6u);
  store.commit();
  EXPECT_EQ(committed_estimate_seqs(path_), "0,1,2,3,4,6");
}

TEST_F(StoreTest, EstimatesOfARunDeletedBehindTheStoresBackAreRefusedAlone) {
  Store store(path_, {.commit_interval = 1h});
  const std::int64_t session = store.begin_session(kLive);
  const std::int64_t link = store.add_link(session, "imu0", "imubridge", "");
  const std::int64_t kept = store.begin_run(session, {.kind = "live"});
  const std::int64_t deleted = store.begin_run(session, {.kind = "replay"});
  store.append_estimate(kept, {.link_id = link, .seq = 0});  // both runs' first rows are accepted
  store.append_estimate(deleted, {.link_id = link, .seq = 0});
  store.commit();
  execute(path_, ("DELETE FROM estimates WHERE run_id = " + std::to_string(deleted) +
                  "; DELETE FROM runs WHERE id = " + std::to_string(deleted))
                     .c_str());

  std::vector<std::string> errors;
  for (std::uint64_t seq = 1; seq <= Store::kMaxWaitingRows; ++seq) {  // the last one starts a burst
    errors.push_back(
        error_of([&] { store.append_estimate(seq % 4 == 0 ? deleted : kept, {.link_id = link, .seq = seq}); }));
  }
  EXPECT_EQ(std::count(errors.begin(), errors.end(), ""), Store::kMaxWaitingRows - 1);
  EXPECT_EQ(errors.back(), path_.string() + ": FOREIGN KEY constraint failed (appending an estimate)");
  const std::size_t kept_rows = Store::kMaxWaitingRows - Store::kMaxWaitingRows / 4;
  EXPECT_EQ(store.pending_rows(), kept_rows);
  store.commit();
  EXPECT_EQ(query(path_, ("SELECT count(*) FROM estimates WHERE run_id = " + std::to_string(kept)).c_str()),
            std::to_string(1 + kept_rows));
  EXPECT_EQ(query(path_, "SELECT count(*) FROM estimates"), std::to_string(1 + kept_rows));
}

TEST_F(StoreTest, MalformedRawCountsAreAnErrorNotACrash) {
  std::int64_t session = 0;
  {
    Store store(path_);
    session = store.begin_session(kLive);
    protocol::Sample s = sample(store.add_link(session, "imu0", "imubridge", ""), 0);
    s.has_raw = true;
    store.append_sample(session, s);
  }
  execute(path_, "UPDATE samples SET raw = x'0102'");  // as a hand-edited or foreign file might have it
  EXPECT_EQ(error_of([&] { samples_of(Store(path_, {.read_only = true}), session); }),
            path_.string() + ": a sample of session 1 has 2 bytes of raw counts, not 40");
}

TEST_F(StoreTest, KilledWriterLosesNothingCommitted) {
  constexpr int kCommitted = 500;
  // More than SQLite's 2 MB page cache holds, so part of the open batch has spilled into the WAL when it dies.
  constexpr int kUncommitted = 30000;
  const pid_t child = fork();
  ASSERT_NE(child, -1);
  if (child == 0) {  // the child only writes, then dies without unwinding; the parent checks
    try {
      Store store(path_, {.commit_interval = 1h});
      const std::int64_t session = store.begin_session(kLive);
      const auto link = store.add_link(session, "imu0", "imubridge", "");
      for (int i = 0; i < kCommitted + kUncommitted; ++i) {
        if (i == kCommitted) store.commit();
        store.append_sample(session, sample(link, static_cast<std::uint64_t>(i)));
      }
      raise(SIGKILL);
    } catch (...) {
    }
    _exit(1);
  }
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << "the writer failed before being killed";
  ASSERT_GT(fs::file_size(path_.string() + "-wal"), 1u << 20) << "the open batch should have reached the WAL";

  EXPECT_EQ(query(path_, "PRAGMA integrity_check"), "ok");
  Store store(path_);  // a restarted recorder, then a reader of what survived
  const std::vector<Session> sessions = store.sessions();
  ASSERT_EQ(sessions.size(), 1u);
  const auto samples = samples_of(store, sessions[0].id);
  ASSERT_EQ(samples.size(), static_cast<std::size_t>(kCommitted));
  for (int i = 0; i < kCommitted; ++i) ASSERT_EQ(samples[i].seq, static_cast<std::uint64_t>(i));
}

// A full disk, as SQLite meets it: a VFS that forwards to the default one, except that while `full` is set every
// write fails with SQLITE_FULL, which is what the unix VFS reports when write() fails with ENOSPC.
class FullDisk {
 public:
  FullDisk() : base_(sqlite3_vfs_find(nullptr)), vfs_(*base_) {
    vfs_.zName = "full-disk";
    vfs_.pAppData = base_;
    vfs_.xOpen = &FullDisk::open;
    sqlite3_vfs_register(&vfs_, 1);
  }
  ~FullDisk() {
    sqlite3_vfs_unregister(&vfs_);
    sqlite3_vfs_register(base_, 1);
    full = false;
  }
  static inline bool full = false;

 private:
  // The unix VFS gives database files and journals different methods: each gets a copy with xWrite replaced.
  struct Patched {
    sqlite3_io_methods methods;  // first, so a file's pMethods leads back to its Patched
    const sqlite3_io_methods* original;
  };
  static inline std::list<Patched> patched_;

  static int open(sqlite3_vfs* vfs, const char* name, sqlite3_file* file, int flags, int* out_flags) {
    auto* base = static_cast<sqlite3_vfs*>(vfs->pAppData);
    const int rc = base->xOpen(base, name, file, flags, out_flags);
    if (rc != SQLITE_OK || file->pMethods == nullptr) return rc;
    auto it =
        std::find_if(patched_.begin(), patched_.end(), [&](const Patched& p) { return p.original == file->pMethods; });
    if (it == patched_.end()) {
      it = patched_.insert(patched_.end(), {*file->pMethods, file->pMethods});
      it->methods.xWrite = &FullDisk::write;
    }
    file->pMethods = &it->methods;
    return rc;
  }
  static int write(sqlite3_file* file, const void* data, int amount, sqlite3_int64 offset) {
    const auto* patched = reinterpret_cast<const Patched*>(file->pMethods);
    return full ? SQLITE_FULL : patched->original->xWrite(file, data, amount, offset);
  }

  sqlite3_vfs* base_;
  sqlite3_vfs vfs_;
};

TEST_F(StoreTest, FullDiskAtCommitLosesOnlyTheBatchAndSaysSo) {
  FullDisk disk;
  {
    Store store(path_, {.commit_interval = 1h});
    const std::int64_t session = store.begin_session(kLive);
    const auto link = store.add_link(session, "imu0", "imubridge", "");
    for (std::uint64_t seq = 0; seq < 10; ++seq) store.append_sample(session, sample(link, seq));
    store.commit();
    for (std::uint64_t seq = 10; seq < 35; ++seq) store.append_sample(session, sample(link, seq));

    FullDisk::full = true;
    try {
      store.commit();
      ADD_FAILURE() << "commit on a full disk succeeded";
    } catch (const StoreError& e) {
      EXPECT_EQ(e.sqlite_code(), SQLITE_FULL);
      EXPECT_EQ(std::string(e.what()), path_.string() +
                                           ": database or disk is full (committing); rolled back the 25 rows "
                                           "appended since the last commit, earlier data is intact");
    }
    EXPECT_EQ(store.pending_rows(), 0u);
    FullDisk::full = false;
    store.append_sample(session, sample(link, 100));  // space came back: recording goes on
  }
  EXPECT_EQ(query(path_, "PRAGMA integrity_check"), "ok");
  Store store(path_, {.read_only = true});
  std::vector<std::uint64_t> seqs;
  for (const auto& s : samples_of(store, store.sessions().at(0).id)) seqs.push_back(s.seq);
  EXPECT_EQ(seqs, (std::vector<std::uint64_t>{0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 100}));
}

TEST_F(StoreTest, FullDiskDropsTheWaitingEstimatesWithTheirBatch) {
  FullDisk disk;
  Store store(path_, {.commit_interval = 1h});
  const std::int64_t session = store.begin_session(kLive);
  const std::int64_t link = store.add_link(session, "imu0", "imubridge", "");
  const std::int64_t run = store.begin_run(session, {.kind = "live"});
  store.append_estimate(run, {.link_id = link, .seq = 0});
  store.commit();
  const std::size_t lost = Store::kMaxWaitingRows + 8;  // a burst in SQLite's transaction, 8 waiting in memory
  for (std::uint64_t seq = 1; seq <= lost; ++seq) store.append_estimate(run, {.link_id = link, .seq = seq});

  FullDisk::full = true;
  EXPECT_EQ(error_of([&] { store.commit(); }),
            path_.string() + ": database or disk is full (committing); rolled back the " + std::to_string(lost) +
                " rows appended since the last commit, earlier data is intact");
  EXPECT_EQ(store.pending_rows(), 0u);
  FullDisk::full = false;
  store.append_estimate(run, {.link_id = link, .seq = 100});
  store.commit();
  EXPECT_EQ(committed_estimate_seqs(path_), "0,100");
}

TEST_F(StoreTest, ReadOnlyStoreNeverChangesTheFile) {
  std::int64_t session = 0;
  {
    Store store(path_);
    session = store.begin_session(kLive);
    const auto link = store.add_link(session, "imu0", "imubridge", "");
    store.append_sample(session, sample(link, 0));
    store.append_chunk(session, link, Direction::rx, 1, 2, std::vector<std::uint8_t>{1, 2});
  }
  const std::vector<char> before = file_bytes(path_);
  {
    Store store(path_, {.read_only = true});
    EXPECT_EQ(samples_of(store, session).size(), 1u);
    const std::string refused = error_of([&] { store.append_sample(session, sample(1, 1)); });
    EXPECT_EQ(refused, path_.string() + ": attempt to write a readonly database (appending a sample)");
    EXPECT_NE(error_of([&] { store.begin_session(kLive); }), "");
    EXPECT_NE(error_of([&] { store.end_session(session, 3); }), "");
  }
  EXPECT_EQ(file_bytes(path_), before);
  // SQLite's WAL index may appear beside it for readers; the log itself must stay empty.
  const fs::path wal = path_.string() + "-wal";
  EXPECT_EQ(fs::exists(wal) ? fs::file_size(wal) : 0u, 0u);
  EXPECT_EQ(query(path_, "SELECT ended_wall_ns IS NULL FROM sessions"), "1");
}

TEST_F(StoreTest, ReadOnlyOpenOfAMissingFileFailsWithoutCreatingIt) {
  const std::string message = error_of([&] { Store store(path_, {.read_only = true}); });
  EXPECT_EQ(message, path_.string() + ": unable to open database file");
  EXPECT_FALSE(fs::exists(path_));
}

TEST_F(StoreTest, NewDatabaseCarriesTheSchemaVersionAndApplicationId) {
  Store store(path_);
  EXPECT_EQ(query(path_, "PRAGMA user_version"), std::to_string(kSchemaVersion));
  EXPECT_EQ(query(path_, "PRAGMA application_id"), std::to_string(0x494D5542));  // "IMUB"
  EXPECT_EQ(query(path_, "PRAGMA journal_mode"), "wal");
}

TEST_F(StoreTest, NewerSchemaIsAOneLineErrorAndTheFileIsLeftAlone) {
  { Store store(path_); }
  execute(path_, "PRAGMA user_version = 7");
  const std::vector<char> before = file_bytes(path_);
  const std::string expected = path_.string() + " was written by a newer imubridge (schema 7, this build reads up to " +
                               std::to_string(kSchemaVersion) + ")";
  EXPECT_EQ(error_of([&] { Store store(path_); }), expected);
  EXPECT_EQ(error_of([&] { Store store(path_, {.read_only = true}); }), expected);
  EXPECT_EQ(file_bytes(path_), before);
}

TEST_F(StoreTest, FileThatIsNotADatabaseIsAOneLineErrorAndIsLeftAlone) {
  std::ofstream(path_) << "time,ax,ay,az\n0,0.1,0.2,9.8\n";  // shorter than a SQLite header
  std::ofstream(dir_ / "big.txt") << std::string(8192, 'x');
  for (const fs::path& path : {path_, dir_ / "big.txt"}) {
    const std::vector<char> before = file_bytes(path);
    EXPECT_EQ(error_of([&] { Store store(path); }), path.string() + ": file is not a database");
    EXPECT_EQ(error_of([&] { Store store(path, {.read_only = true}); }), path.string() + ": file is not a database");
    EXPECT_EQ(file_bytes(path), before);
  }
}

TEST_F(StoreTest, AnotherProgramsDatabaseIsRefusedAndLeftAlone) {
  execute(path_, "CREATE TABLE contacts (name TEXT)");
  const std::vector<char> before = file_bytes(path_);
  EXPECT_EQ(error_of([&] { Store store(path_); }),
            path_.string() + " is a SQLite database of another program (application_id 0), not an imubridge one");
  EXPECT_EQ(file_bytes(path_), before);
}

// A session begun, given a chunk and an event, and never ended, by a child process that then exits without ending
// it, as a recorder killed mid-flight does. Returns the session's id.
std::int64_t session_of_a_process_that_died(const fs::path& path, std::int64_t chunk_wall_ns,
                                            std::int64_t event_wall_ns) {
  const pid_t child = ::fork();
  if (child == 0) {
    try {
      Store store(path);
      const auto session = store.begin_session({.kind = "live", .source = "died", .started_wall_ns = 1000});
      const auto link = store.add_link(session, "imu", "imubridge", "/dev/null");
      store.append_chunk(session, link, Direction::rx, 70, chunk_wall_ns, std::vector<std::uint8_t>{1, 2});
      store.append_event(session, {.mono_ns = 80, .wall_ns = event_wall_ns, .kind = "note", .detail = "x"});
      store.commit();
      ::_exit(static_cast<int>(session));  // no destructor, no ending
    } catch (...) {
      ::_exit(0);
    }
  }
  int status = 0;
  ::waitpid(child, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 0;
}

TEST_F(StoreTest, ASessionWhoseWriterDiedIsEndedAsInterruptedAtItsLastStoredTime) {
  ASSERT_EQ(session_of_a_process_that_died(path_, 5000, 4000), 1);  // its chunk is its latest row
  ASSERT_EQ(session_of_a_process_that_died(path_, 5000, 6000), 2);  // its event is
  Store store(path_);
  const auto ours = store.begin_session({.kind = "live", .started_wall_ns = 2000});
  const auto ended = store.end_interrupted_sessions();
  ASSERT_EQ(ended.size(), 2u);
  EXPECT_EQ(ended[0].session, 1);
  EXPECT_EQ(ended[0].ended_wall_ns, 5000);
  EXPECT_EQ(ended[1].session, 2);
  EXPECT_EQ(ended[1].ended_wall_ns, 6000);

  const auto sessions = store.sessions();
  ASSERT_EQ(sessions.size(), 3u);
  EXPECT_EQ(sessions[0].ended_wall_ns, 5000);
  EXPECT_TRUE(sessions[0].interrupted);
  EXPECT_STREQ(state_name(sessions[0]), "interrupted");
  EXPECT_STREQ(state_name(sessions[1]), "interrupted");
  EXPECT_EQ(sessions[2].id, ours);
  EXPECT_STREQ(state_name(sessions[2]), "open") << "its writer, this process, runs";
  EXPECT_EQ(sessions[2].writer, this_process());
  // The interruption is an event at the session's last stored time, in the monotonic time of that row.
  const auto events = store.events(1);
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[1].kind, "interrupted");
  EXPECT_EQ(events[1].wall_ns, 5000);
  EXPECT_EQ(events[1].mono_ns, 70);
  EXPECT_NE(events[1].detail.find("process " + std::to_string(sessions[0].writer->pid)), std::string::npos);
  EXPECT_EQ(store.events(2).back().mono_ns, 80);

  EXPECT_TRUE(store.end_interrupted_sessions().empty()) << "each is ended once";
  EXPECT_EQ(store.events(1).size(), 2u);
}

TEST_F(StoreTest, AWriterIsTakenForDeadAfterARebootOrWhenItsPidNowNamesAnotherProcess) {
  {
    Store store(path_);
    for (int i = 0; i < 3; ++i) store.begin_session({.kind = "live", .started_wall_ns = 1000 + i});
  }
  // All three name this process, which runs; what an identity from another boot, or from an earlier holder of our
  // pid, would look like:
  execute(path_, "UPDATE sessions SET writer_boot_id = 'another boot' WHERE id = 1");
  execute(path_, "UPDATE sessions SET writer_start_ticks = writer_start_ticks - 1 WHERE id = 2");
  Store store(path_);
  const auto ended = store.end_interrupted_sessions();
  ASSERT_EQ(ended.size(), 2u);
  EXPECT_EQ(ended[0].session, 1);
  EXPECT_EQ(ended[0].ended_wall_ns, 1000) << "no rows: it ends where it started";
  EXPECT_EQ(ended[1].session, 2);
  EXPECT_STREQ(state_name(store.sessions()[2]), "open");
}

TEST_F(StoreTest, AFileOfSchemaVersion1OpensReadOnlyAsItIsAndReadWriteUpgraded) {
  {
    Database db(path_, false);
    migrate(db, migrations().first(1));
    db.exec(
        "INSERT INTO sessions (kind, source, started_wall_ns, config, software_version) "
        "VALUES ('live', 'old', 10, '{}', '0.9')");
  }
  const std::vector<char> before = file_bytes(path_);
  {
    const Store reader(path_, {.read_only = true});
    const auto sessions = reader.sessions();
    ASSERT_EQ(sessions.size(), 1u);
    EXPECT_EQ(sessions[0].info.source, "old");
    EXPECT_FALSE(sessions[0].writer.has_value());
    EXPECT_STREQ(state_name(sessions[0]), "open");
  }
  EXPECT_EQ(file_bytes(path_), before);
  Store store(path_);
  EXPECT_EQ(query(path_, "PRAGMA user_version"), "2");
  EXPECT_TRUE(store.end_interrupted_sessions().empty()) << "no writer recorded: nothing says it died";
  EXPECT_STREQ(state_name(store.sessions()[0]), "open");
}

// Hypothetical schema versions 1 and 2, to exercise the mechanism apart from this build's steps.
constexpr MigrationStep kSteps[] = {
    [](Database& db) { db.exec("CREATE TABLE t (x INTEGER)"); },
    [](Database& db) { db.exec("ALTER TABLE t ADD COLUMN y TEXT DEFAULT 'two'"); },
};

TEST_F(StoreTest, MigrationRunsOnlyTheMissingSteps) {
  Database db(path_, false);
  migrate(db, std::span(kSteps).first(1));
  EXPECT_EQ(db.query_int("PRAGMA user_version"), 1);
  db.exec("INSERT INTO t (x) VALUES (41)");
  migrate(db, kSteps);  // step 0 again would fail: t exists
  EXPECT_EQ(db.query_int("PRAGMA user_version"), 2);
  EXPECT_EQ(db.query_int("SELECT count(*) FROM t WHERE x = 41 AND y = 'two'"), 1);
  migrate(db, kSteps);
  EXPECT_EQ(db.query_int("PRAGMA user_version"), 2);
}

TEST_F(StoreTest, FailingMigrationLeavesTheFileAtItsOldVersion) {
  const MigrationStep steps[] = {kSteps[0], [](Database& db) { db.exec("ALTER TABLE missing ADD COLUMN z"); }};
  Database db(path_, false);
  const std::string message = error_of([&] { migrate(db, steps); });
  EXPECT_EQ(message, path_.string() + ": no such table: missing");
  EXPECT_FALSE(db.in_transaction());
  EXPECT_EQ(db.query_int("PRAGMA user_version"), 0);
  EXPECT_EQ(db.query_int("SELECT count(*) FROM sqlite_schema"), 0) << "step 0 was rolled back with step 1";
}

TEST_F(StoreTest, MigrationRefusesADatabaseNewerThanItsSteps) {
  Database db(path_, false);
  migrate(db, kSteps);
  EXPECT_EQ(error_of([&] { migrate(db, std::span(kSteps).first(1)); }),
            path_.string() + " was written by a newer imubridge (schema 2, this build reads up to 1)");
  EXPECT_EQ(db.query_int("PRAGMA user_version"), 2);
}

}  // namespace
}  // namespace imubridge::store
