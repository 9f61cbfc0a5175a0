// `imubridge export --format mcap` read back by the MCAP project's own reader: @mcap/core from npm, run by node on
// tests/mcap_read.cjs, must give every message of the session, equal to what the store holds.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "store/store.hpp"
#include "tests/support/json_numbers.hpp"
#include "tests/support/npm_packages.hpp"
#include "tests/support/paper_params.hpp"
#include "tests/support/run_command.hpp"
#include "tests/support/temp_dir.hpp"

namespace imubridge::test {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// What tests/mcap_read.cjs prints for `file`, each message's text parsed here into "data" (exact 64-bit integers).
json read_with_mcap_core(const fs::path& file) {
  const fs::path out = file.string() + ".read.json";
  const fs::path err = file.string() + ".read.err";
  const std::string command = "NODE_PATH=" + npm_node_path() + " node " + IMUBRIDGE_SOURCE_DIR "/tests/mcap_read.cjs " +
                              file.string() + " >" + out.string() + " 2>" + err.string();
  const int status = std::system(command.c_str());
  if (status != 0) throw std::runtime_error("mcap_read.cjs failed: " + slurp(err));
  json read = json::parse(slurp(out));
  for (auto& [topic, channel] : read["topics"].items()) {
    for (auto& message : channel["messages"]) message["data"] = json::parse(message["text"].get<std::string>());
  }
  return read;
}

class McapExport : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { install_error_ = install_npm_packages(); }
  void SetUp() override { ASSERT_EQ(install_error_, "") << install_error_; }

  // A simulated flight with its truth as reference, and a replay run with the paper's parameters for estimates.
  std::int64_t simulated_session(double seconds) {
    const auto sim =
        run_imubridge("sim --scenario paper --seed 3 --duration " + std::to_string(seconds) + " --db " + db_.string());
    EXPECT_EQ(sim.exit_code, 0) << sim.err;
    const std::int64_t session = std::stoll(sim.out.substr(sim.out.rfind('\n', sim.out.size() - 2) + 1));
    const fs::path params = dir_ / "PARAMS.json";
    std::ofstream(params) << json(paper_params()).dump(2);
    const auto replay = run_imubridge("replay --db " + db_.string() + " --session " + std::to_string(session) +
                                      " --params " + params.string());
    EXPECT_EQ(replay.exit_code, 0) << replay.err;
    return session;
  }

  static inline std::string install_error_;
  TempDir dir_;
  fs::path db_ = dir_ / "flights.db";
};

// What the store holds of one session and its one run: what the export must carry, message for message.
struct StoredSession {
  std::vector<protocol::Sample> samples;
  std::vector<store::Estimate> estimates;
  std::vector<store::ReferenceRow> reference;
  std::vector<store::Event> events;
};

StoredSession read_stored_session(const fs::path& db, std::int64_t session) {
  const store::Store store(db, {.read_only = true});
  StoredSession stored;
  store.for_each_sample(session, std::nullopt, [&](const protocol::Sample& s) { stored.samples.push_back(s); });
  const auto runs = store.runs(session);
  EXPECT_EQ(runs.size(), 1u);
  if (!runs.empty()) {
    store.for_each_estimate(runs[0].id, [&](const store::Estimate& e) { stored.estimates.push_back(e); });
  }
  store.for_each_reference(session, [&](const store::ReferenceRow& row) { stored.reference.push_back(row); });
  stored.events = store.events(session);
  return stored;
}

// The summary, the index and a plain pass from the start agree with the store's counts.
void expect_counts_agree(const json& read, const StoredSession& stored) {
  const json& topics = read["topics"];
  const std::map<std::string, std::size_t> want{{"/sim/imu", stored.samples.size()},
                                                {"/sim/estimate", stored.estimates.size()},
                                                {"/reference/pose", stored.reference.size()},
                                                {"/reference/velocity", stored.reference.size()},
                                                {"/events", stored.events.size()}};
  ASSERT_EQ(topics.size(), want.size()) << topics.dump().substr(0, 500);
  std::size_t total = 0;
  for (const auto& [topic, n] : want) {
    ASSERT_TRUE(topics.contains(topic)) << topic;
    EXPECT_EQ(topics[topic]["messages"].size(), n) << topic;
    EXPECT_EQ(read["statistics"]["channel_message_counts"][topic], std::to_string(n)) << topic;
    EXPECT_EQ(read["stream"]["messages"][topic], n) << topic;
    EXPECT_EQ(topics[topic]["message_encoding"], "json");
    EXPECT_EQ(topics[topic]["schema_encoding"], "jsonschema");
    EXPECT_TRUE(topics[topic]["schema_valid_json"].get<bool>()) << topic;
    EXPECT_EQ(topics[topic]["invalid_json"], 0) << topic << ": JSON.parse refused messages";
    total += n;
  }
  EXPECT_EQ(read["indexed_messages"], total);
  EXPECT_EQ(read["statistics"]["message_count"], std::to_string(total));
  EXPECT_TRUE(read["in_time_order"].get<bool>());
  EXPECT_TRUE(read["stream"]["footer"].get<bool>());
  EXPECT_GT(read["chunk_indexes"].get<int>(), 4) << "a 30 s flight spans several chunks";
  EXPECT_EQ(read["statistics"]["chunk_count"], read["chunk_indexes"]);
  EXPECT_EQ(topics["/events"]["schema"], "foxglove.Log");
  EXPECT_EQ(topics["/reference/pose"]["schema"], "foxglove.PoseInFrame");
  EXPECT_EQ(topics["/sim/imu"]["metadata"]["protocol"], "imubridge");
}

// Samples, message for message; times on the monotonic line through the link's first sample.
void expect_samples_equal(const json& sample_messages, const std::vector<protocol::Sample>& samples) {
  const std::int64_t origin = samples.front().recv_mono_ns;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const auto& s = samples[i];
    const json& m = sample_messages[i];
    const json& d = m["data"];
    const std::int64_t session_ns = (s.device_time_us - samples.front().device_time_us) * 1000;
    ASSERT_EQ(m["sequence"], i);
    ASSERT_EQ(m["log_time"], std::to_string(origin + session_ns)) << i;
    ASSERT_EQ(d["session_t_s"].get<double>(), static_cast<double>(session_ns) / 1e9) << i;
    ASSERT_EQ(d["seq"], s.seq);
    ASSERT_EQ(d["device_time_us"], s.device_time_us);
    ASSERT_EQ(d["recv_mono_ns"], s.recv_mono_ns);
    const char* axes[] = {"ax", "ay", "az", "gx", "gy", "gz"};
    for (int k = 0; k < 3; ++k) {
      ASSERT_TRUE(json_holds(d[axes[k]], s.accel[k])) << i << axes[k];
      ASSERT_TRUE(json_holds(d[axes[3 + k]], s.gyro[k])) << i << axes[3 + k];
    }
    ASSERT_TRUE(d["mx"].is_null() == !s.has_mag);
  }
  EXPECT_EQ(sample_messages.front()["log_time"], std::to_string(origin));
}

void expect_estimates_equal(const json& estimate_messages, const StoredSession& stored) {
  const std::int64_t first_device_us = stored.samples.front().device_time_us;
  for (std::size_t i = 0; i < stored.estimates.size(); ++i) {
    const auto& e = stored.estimates[i];
    const json& d = estimate_messages[i]["data"];
    ASSERT_EQ(d["seq"], e.seq) << i;
    ASSERT_TRUE(json_holds(d["device_t_s"], e.t_s)) << i;
    ASSERT_TRUE(json_holds(d["fx"], e.fx) && json_holds(d["fy"], e.fy)) << i;
    ASSERT_TRUE(json_holds(d["vx"], e.vx) && json_holds(d["vy"], e.vy)) << i;
    ASSERT_TRUE(json_holds(d["var_vx"], e.var_vx) && json_holds(d["var_vy"], e.var_vy)) << i;
    // An estimate has its sample's session time.
    const double sample_t = (static_cast<double>(std::llround(e.t_s * 1e6)) - first_device_us) / 1e6;
    ASSERT_EQ(d["session_t_s"].get<double>(), sample_t) << i;
  }
}

void expect_reference_equal(const json& topics, const StoredSession& stored) {
  const std::int64_t origin = stored.samples.front().recv_mono_ns;
  const json& poses = topics["/reference/pose"]["messages"];
  const json& velocities = topics["/reference/velocity"]["messages"];
  for (std::size_t i = 0; i < stored.reference.size(); ++i) {
    const auto& row = stored.reference[i];
    const json& pose = poses[i]["data"]["pose"];
    ASSERT_EQ(poses[i]["log_time"], std::to_string(row.t_ns)) << i;
    ASSERT_EQ(poses[i]["data"]["timestamp"]["sec"], row.t_ns / 1'000'000'000) << i;
    ASSERT_EQ(poses[i]["data"]["timestamp"]["nsec"], row.t_ns % 1'000'000'000) << i;
    ASSERT_TRUE(json_holds(pose["position"]["x"], row.position[0]) &&
                json_holds(pose["position"]["z"], row.position[2]))
        << i;
    ASSERT_TRUE(json_holds(pose["orientation"]["w"], row.quat_wxyz[0]) &&
                json_holds(pose["orientation"]["x"], row.quat_wxyz[1]))
        << i;
    ASSERT_TRUE(json_holds(velocities[i]["data"]["vx"], (*row.velocity)[0])) << i;
    ASSERT_EQ(velocities[i]["data"]["session_t_s"].get<double>(), static_cast<double>(row.t_ns - origin) / 1e9);
  }
}

void expect_events_equal(const json& logs, const std::vector<store::Event>& events) {
  for (std::size_t i = 0; i < events.size(); ++i) {
    const auto& e = events[i];
    const json& d = logs[i]["data"];
    ASSERT_EQ(d["kind"], e.kind) << i;
    ASSERT_EQ(d["detail"], e.detail) << i;
    ASSERT_EQ(d["count"], e.count) << i;
    ASSERT_EQ(d["wall_ns"], e.wall_ns) << i;
    ASSERT_EQ(logs[i]["log_time"], std::to_string(e.mono_ns)) << i;
    std::string message = e.kind + (e.count != 1 ? " (" + std::to_string(e.count) + " times)" : "");
    if (!e.detail.empty()) message += ": " + e.detail;
    ASSERT_EQ(d["message"], message) << i;
    ASSERT_EQ(d["name"], e.link_id ? "sim" : "session") << i;
  }
}

TEST_F(McapExport, EveryMessageReadsBackThroughMcapCoreEqualToTheStore) {
  const std::int64_t session = simulated_session(30);
  const fs::path file = dir_ / "flight.mcap";
  const auto r = run_imubridge("export --db " + db_.string() + " --session " + std::to_string(session) +
                               " --format mcap --out " + file.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json read = read_with_mcap_core(file);
  const StoredSession stored = read_stored_session(db_, session);
  ASSERT_GT(stored.samples.size(), 1000u);
  ASSERT_GT(stored.estimates.size(), 1000u);
  ASSERT_GT(stored.reference.size(), 1000u);
  ASSERT_FALSE(stored.events.empty());

  const json& topics = read["topics"];
  expect_counts_agree(read, stored);
  expect_samples_equal(topics["/sim/imu"]["messages"], stored.samples);
  expect_estimates_equal(topics["/sim/estimate"]["messages"], stored);
  expect_reference_equal(topics, stored);
  EXPECT_EQ(read["statistics"]["message_start_time"],
            std::to_string(std::min(stored.samples.front().recv_mono_ns, stored.reference.front().t_ns)));
  expect_events_equal(topics["/events"]["messages"], stored.events);
}

TEST_F(McapExport, SessionWithoutRunsHasNoEstimateChannelAndEmptyTextSurvives) {
  store::Store store(db_);
  const auto session = store.begin_session({.kind = "test", .config = "{}"});
  const auto link = store.add_link(session, "imu0", "imubridge", "test");
  store.append_sample(session, {.link_id = link,
                                .seq = 0,
                                .device_time_us = 1000,
                                .recv_mono_ns = 50'000'000,
                                .accel = {0, 0, -9.8},
                                .gyro = {0, 0, 0}});
  store.append_sample(session, {.link_id = link,
                                .seq = 1,
                                .device_time_us = 2000,
                                .recv_mono_ns = 51'000'000,
                                .accel = {0.5, 0, -9.8},
                                .gyro = {0, 0.25, 0}});
  // Before the first sample (its session time is negative) and with bytes that are not UTF-8.
  store.append_event(
      session,
      {.mono_ns = 40'000'000, .wall_ns = 1, .kind = "note", .count = 1, .detail = std::string("bad \xff byte")});
  store.commit();
  const fs::path file = dir_ / "small.mcap";
  const auto r = run_imubridge("export --db " + db_.string() + " --session " + std::to_string(session) +
                               " --format mcap --out " + file.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json read = read_with_mcap_core(file);
  EXPECT_EQ(read["topics"].size(), 2u) << read["topics"].dump();  // /imu0/imu and /events
  ASSERT_EQ(read["topics"]["/imu0/imu"]["messages"].size(), 2u);
  const json& second = read["topics"]["/imu0/imu"]["messages"][1];
  EXPECT_EQ(second["log_time"], "51000000");
  EXPECT_EQ(second["data"]["session_t_s"].get<double>(), 0.001);
  EXPECT_EQ(second["data"]["gy"].get<double>(), 0.25);
  const json& note = read["topics"]["/events"]["messages"][0];
  EXPECT_EQ(note["data"]["session_t_s"].get<double>(), -0.01);
  EXPECT_EQ(note["data"]["detail"], "bad \xef\xbf\xbd byte");  // U+FFFD for the byte that is not UTF-8
  EXPECT_EQ(note["data"]["level"], 2);
}

TEST_F(McapExport, MistakesAreOneLineAndWriteNothing) {
  const fs::path file = dir_ / "out.mcap";
  const std::int64_t session = simulated_session(1);
  const std::string base = "export --db " + db_.string() + " --format mcap";
  for (const auto& [args, message] : std::vector<std::pair<std::string, std::string>>{
           {base + " --session 99 --out " + file.string(), "no session 99"},
           {base + " --session " + std::to_string(session), "give --out FILE.mcap"},
           {base + " --session " + std::to_string(session) + " --what samples --out " + file.string(),
            "leave out --what"},
       }) {
    const auto r = run_imubridge(args);
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.err;
    EXPECT_EQ(count_lines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(message), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(file)) << args;
  }
}

}  // namespace
}  // namespace imubridge::test
