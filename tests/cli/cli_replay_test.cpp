// `imubridge replay`, `import euroc` and `export` as a user runs them, on sessions made by `imubridge sim`.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "pipeline/estimation_stage.hpp"
#include "sim/scenario.hpp"
#include "store/store.hpp"
#include "tests/support/paper_params.hpp"
#include "tests/support/run_command.hpp"

namespace imubridge::test {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string last_line(const std::string& out) {
  std::istringstream in(out);
  std::string line, last;
  while (std::getline(in, line)) last = line;
  return last;
}

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

bool same(double a, double b) { return a == b || (std::isnan(a) && std::isnan(b)); }

class ReplayCommand : public ::testing::Test {
 protected:
  fs::path dir_ = fs::temp_directory_path() / ("imubridge_cli_replay_" + std::to_string(::getpid()));
  fs::path db_ = dir_ / "flights.db";
  void SetUp() override { fs::create_directories(dir_); }
  void TearDown() override { fs::remove_all(dir_); }

  // Runs the program, expects success, and returns the id it prints alone on its last line.
  std::int64_t run_for_id(const std::string& args) {
    const auto r = run_imubridge(args);
    EXPECT_EQ(r.exit_code, 0) << args << "\n" << r.err;
    return std::stoll(last_line(r.out));
  }
  std::int64_t simulate(const std::string& protocol, double seconds) {
    return run_for_id("sim --scenario paper --seed 5 --duration " + std::to_string(seconds) + " --protocol " +
                      protocol + " --db " + db_.string());
  }
  std::string replay_args(std::int64_t session) const {
    return "replay --db " + db_.string() + " --session " + std::to_string(session);
  }

  // The paper's parameters as PARAMS.json, so that the estimates carry velocities.
  std::pair<fs::path, estimator::ModelParams> paper_params_file() const {
    const estimator::ModelParams p = paper_params();
    const fs::path path = dir_ / "PARAMS.json";
    std::ofstream(path) << json(p).dump(2);
    return {path, p};
  }
  void expect_replay_reproduces_live_run(const std::string& sim_args, const std::string& link_config,
                                         std::vector<std::string>& mismatches);
};

// What the session's stored samples give through the EstimationStage, link by link: replay decodes the same
// bytes again, so it must get exactly this.
std::map<std::int64_t, std::vector<store::Estimate>> estimate_stored_samples(const store::Store& store,
                                                                             std::int64_t session,
                                                                             const estimator::ModelParams& params) {
  pipeline::EstimationStage stage(params);
  std::map<std::int64_t, std::vector<store::Estimate>> out;
  store.for_each_sample(session, std::nullopt, [&](protocol::Sample s) {
    s.source.link = static_cast<std::uint32_t>(s.link_id);  // a stored sample's stream: its store link
    if (auto e = stage.update(s)) {
      e->link_id = s.link_id;  // the stage leaves storing to whoever stores: it is the sample's link
      out[s.link_id].push_back(*e);
    }
  });
  return out;
}

std::map<std::int64_t, std::vector<store::Estimate>> stored_estimates(const store::Store& store, std::int64_t run) {
  std::map<std::int64_t, std::vector<store::Estimate>> out;
  store.for_each_estimate(run, [&](const store::Estimate& e) { out[e.link_id].push_back(e); });
  return out;
}

void expect_same_estimates(const std::map<std::int64_t, std::vector<store::Estimate>>& a,
                           const std::map<std::int64_t, std::vector<store::Estimate>>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (const auto& [link, list] : a) {
    ASSERT_TRUE(b.contains(link));
    ASSERT_EQ(list.size(), b.at(link).size());
    for (std::size_t i = 0; i < list.size(); ++i) {
      const auto &x = list[i], &y = b.at(link)[i];
      if (!(x.seq == y.seq && same(x.t_s, y.t_s) && same(x.fx, y.fx) && same(x.fy, y.fy) && same(x.vx, y.vx) &&
            same(x.vy, y.vy) && same(x.var_vx, y.var_vx) && same(x.var_vy, y.var_vy))) {
        ADD_FAILURE() << "link " << link << ": estimate " << i << " of " << list.size() << " differs, the first to";
        return;
      }
    }
  }
}

TEST_F(ReplayCommand, XbeeAndMavlinkSessionsReplayToWhatTheirStoredSamplesGive) {
  const auto [params_path, params] = paper_params_file();
  for (const std::string protocol : {"xbee", "mavlink"}) {
    const std::int64_t session = simulate(protocol, 2.0);
    const auto r = run_imubridge(replay_args(session) + " --params " + params_path.string());
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const std::int64_t run = std::stoll(last_line(r.out));
    EXPECT_NE(r.err.find("400 samples"), std::string::npos) << r.err;  // 2 s at 200 Hz
    const std::int64_t paced = run_for_id(replay_args(session) + " --params " + params_path.string() + " --speed 20");

    const store::Store store(db_, {.read_only = true});
    const auto want = estimate_stored_samples(store, session, params);
    ASSERT_EQ(want.size(), 1u) << protocol;  // xbee: the radio's link, not the port's
    EXPECT_TRUE(std::isfinite(want.begin()->second.front().vx));
    expect_same_estimates(stored_estimates(store, run), want);
    expect_same_estimates(stored_estimates(store, paced), want);
    EXPECT_EQ(store.runs(session).front().info.kind, "replay");
  }
}

// Starts the program as a child of its own, with stdout and stderr into `log`; returns its process id.
pid_t spawn_imubridge(const std::vector<std::string>& args, const fs::path& log) {
  std::vector<std::string> words{IMUBRIDGE_BIN};
  words.insert(words.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& word : words) argv.push_back(word.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t files;
  posix_spawn_file_actions_init(&files);
  posix_spawn_file_actions_addopen(&files, STDOUT_FILENO, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&files, STDOUT_FILENO, STDERR_FILENO);
  pid_t pid = -1;
  if (posix_spawn(&pid, IMUBRIDGE_BIN, &files, nullptr, argv.data(), environ) != 0) pid = -1;
  posix_spawn_file_actions_destroy(&files);
  return pid;
}

// The real thing: `imubridge run` records a simulated vehicle streaming on a pty, estimating live; replaying its
// session with the live run's parameters must give that run's estimates exactly.
// sim -> pty -> `imubridge run`, estimating live with the paper's parameters, then replay with the live run's
// parameters: the replay's estimates must be the live run's, bit for bit. `link_config` is the [[link]] table's
// lines beyond its name, device and protocol; `sim_args` what the vehicle adds to its command. `mismatches` gets the
// session's imu_axes_mismatch events.
void ReplayCommand::expect_replay_reproduces_live_run(const std::string& sim_args, const std::string& link_config,
                                                      std::vector<std::string>& mismatches) {
  const auto [params_path, params] = paper_params_file();
  const fs::path tty = dir_ / "ttyVehicle";
  const fs::path config = dir_ / "run.toml";
  std::ofstream(config) << "[[link]]\nname = \"imu0\"\ndevice = \"" << tty.string() << "\"\nprotocol = \"xbee\"\n"
                        << link_config;
  CommandResult vehicle;
  std::thread sim([&] {
    vehicle = run_imubridge("sim --scenario paper --seed 2 --duration 2 --protocol xbee " + sim_args + " --pty " +
                            tty.string());
  });
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (!fs::is_symlink(tty) && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  const pid_t daemon = spawn_imubridge({"run", "--db", db_.string(), "--config", config.string(), "--params",
                                        params_path.string(), "--log-level", "warn"},
                                       dir_ / "run.log");
  sim.join();
  ASSERT_GT(daemon, 0);
  ASSERT_EQ(vehicle.exit_code, 0) << vehicle.err;
  ::kill(daemon, SIGTERM);  // the vehicle is done; the daemon ends its session cleanly
  int status = 0;
  ASSERT_EQ(::waitpid(daemon, &status, 0), daemon);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << slurp(dir_ / "run.log");

  std::int64_t session = 0, live = 0;
  {
    const store::Store store(db_, {.read_only = true});
    session = store.sessions().at(0).id;
    live = store.runs(session).at(0).id;
    ASSERT_EQ(store.runs(session).at(0).info.kind, "live");
  }
  const std::int64_t replayed = run_for_id(replay_args(session));  // default: the live run's parameters
  const store::Store store(db_, {.read_only = true});
  const auto want = stored_estimates(store, live);
  ASSERT_EQ(want.size(), 1u);  // the radio's link
  EXPECT_GT(want.begin()->second.size(), 100u);
  EXPECT_TRUE(std::isfinite(want.begin()->second.back().vx));
  expect_same_estimates(stored_estimates(store, replayed), want);
  for (const store::Event& e : store.events(session)) {
    if (e.kind == "imu_axes_mismatch") mismatches.push_back(e.detail);
  }
}

TEST_F(ReplayCommand, ReplayingADaemonSessionReproducesItsLiveRun) {
  std::vector<std::string> mismatches;
  expect_replay_reproduces_live_run("", "", mismatches);
  EXPECT_TRUE(mismatches.empty()) << mismatches.front();
}

// A radio's samples take the axes declared for the link they are heard through, live as in replay. Declared
// wrongly here (the IMU is FRD, the configuration says FLU), the declaration is what both runs apply, and the live
// run records that the data contradict it; a radio that fell back to detecting its own axes would estimate in FRD
// live and in FLU in replay, and say nothing.
TEST_F(ReplayCommand, ARadioTakesItsLinksDeclaredAxesLiveAsInReplay) {
  std::vector<std::string> mismatches;
  expect_replay_reproduces_live_run("--imu-axes frd", "axes = \"flu\"\n", mismatches);
  EXPECT_EQ(mismatches.size(), 1u);
}

// A model fitted with the reference flies its own flight as that flight's in replay, though the reference began
// after the IMU and its span dropped the first samples the fit saw: it is not taken for a calibration carried to
// another flight (whose offset and wind the live filter would count as unknown).
TEST_F(ReplayCommand, AModelFittedWithALateReferenceKnowsItsOwnFlight) {
  const std::int64_t session = simulate("imubridge", 30);
  const std::string late = "sqlite3 " + db_.string() +
                           " 'DELETE FROM reference WHERE t_ns < (SELECT MIN(t_ns) FROM reference) + 2000000000'";
  ASSERT_EQ(std::system(late.c_str()), 0);
  const fs::path params = dir_ / "own.json";
  const auto fitted = run_imubridge("identify --db " + db_.string() + " --session " + std::to_string(session) +
                                    " --model paper --velocity reference --train 0:60% --validate 60%: --out " +
                                    params.string());
  ASSERT_EQ(fitted.exit_code, 0) << fitted.err;
  const auto replayed = run_imubridge(replay_args(session) + " --params " + params.string());
  ASSERT_EQ(replayed.exit_code, 0) << replayed.err;

  const store::Store store(db_, {.read_only = true});
  const auto runs = store.runs(session);
  ASSERT_EQ(runs.size(), 1u);
  const json flown = json::parse(runs[0].info.params_json);
  EXPECT_EQ(flown.at("conditions").at("flight"), json::parse(slurp(params)).at("conditions").at("flight"));
  EXPECT_FALSE(flown.at("conditions").at("transferred").get<bool>());
}

TEST_F(ReplayCommand, FromToReplaysTheChunksReceivedInTheWindow) {
  const std::int64_t session = simulate("imubridge", 2.0);  // one frame per chunk, received at the sample's time
  const std::int64_t run = run_for_id(replay_args(session) + " --from 0.5 --to 1.5");
  const store::Store store(db_, {.read_only = true});
  std::vector<std::uint64_t> window;
  store.for_each_sample(session, std::nullopt, [&](const protocol::Sample& s) {
    if (s.recv_mono_ns >= 500'000'000 && s.recv_mono_ns < 1'500'000'000) window.push_back(s.seq);
  });
  ASSERT_EQ(window.size(), 200u);
  std::vector<std::uint64_t> estimated;
  store.for_each_estimate(run, [&](const store::Estimate& e) { estimated.push_back(e.seq); });
  // The estimator starts fresh at --from: two samples at each end of the window wait for neighbours in vain.
  EXPECT_EQ(estimated, std::vector<std::uint64_t>(window.begin() + 2, window.end() - 2));

  const auto backwards = run_imubridge(replay_args(session) + " --from 1.5 --to 0.5");
  EXPECT_EQ(backwards.exit_code, 2);
  EXPECT_EQ(count_lines(backwards.err), 1) << backwards.err;
}

TEST_F(ReplayCommand, ToPtyReemitsTheRecordedBytesOnAPseudoTerminal) {
  const std::int64_t session = simulate("imubridge", 1.0);
  std::vector<std::uint8_t> want;
  {
    const store::Store store(db_, {.read_only = true});
    store.for_each_chunk(session, std::nullopt,
                         [&](const store::Chunk& c) { want.insert(want.end(), c.bytes.begin(), c.bytes.end()); });
  }
  const fs::path link = dir_ / "ttyIMU";
  CommandResult result;
  std::thread replayer([&] { result = run_imubridge(replay_args(session) + " --to-pty " + link.string()); });

  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (!fs::is_symlink(link) && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  const int fd = ::open(link.c_str(), O_RDONLY | O_NOCTTY);
  std::vector<std::uint8_t> got;
  if (fd >= 0) {
    std::uint8_t buffer[4096];
    pollfd pfd{fd, POLLIN, 0};
    while (got.size() < want.size() && std::chrono::steady_clock::now() < deadline && ::poll(&pfd, 1, 100) >= 0) {
      if (!(pfd.revents & POLLIN)) continue;
      const ssize_t n = ::read(fd, buffer, sizeof buffer);
      if (n <= 0) break;  // the replay closed the pty
      got.insert(got.end(), buffer, buffer + n);
    }
    ::close(fd);
  }
  replayer.join();
  ASSERT_GE(fd, 0) << "could not open " << link;
  EXPECT_EQ(result.exit_code, 0) << result.err;
  EXPECT_EQ(got.size(), want.size());
  EXPECT_EQ(got, want);  // the tail too: the replay waits for its reader before closing the pty
  EXPECT_FALSE(fs::exists(fs::symlink_status(link))) << "the symlink outlived the replay";
}

TEST_F(ReplayCommand, ImportsAMessyEurocFixtureReportingEverySkippedRow) {
  const fs::path fixture = fs::path(IMUBRIDGE_SOURCE_DIR) / "tests/data/euroc_junk";
  const auto r = run_imubridge("import euroc " + fixture.string() + " --reference " +
                               (fixture / "reference_tum.txt").string() + " --db " + db_.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto err = r.err;
  const std::string imu = (fixture / "mav0/imu0/data.csv").string(), tum = (fixture / "reference_tum.txt").string();
  for (const std::string& expected :
       {"\n1 row of " + imu + " skipped: 3 fields, expected 7 (line 5)\n",
        "\n4 rows of " + imu + " skipped: not a finite number (lines 8-9, 16-17)\n",
        "\n2 rows of " + imu + " skipped: empty field (lines 14-15)\n",
        "\n1 row of " + imu + " skipped: timestamp not after the previous row's (line 11)\n",
        "\nwarning: 1 row of " + imu + " clipped: accel beyond +-65.534 m/s^2 (line 12)\n",
        std::string("\nreference: 11 rows"),
        "\n1 row of " + tum + " skipped: quaternion not of unit length (line 15)\n"}) {
    EXPECT_NE(err.find(expected), std::string::npos) << "missing \"" << expected << "\" in:\n" << err;
  }
  const std::int64_t session = std::stoll(last_line(r.out));
  // An imported session starts from bytes, so it replays like a recorded one: 7 samples, 3 estimates.
  const auto replay = run_imubridge(replay_args(session));
  ASSERT_EQ(replay.exit_code, 0) << replay.err;
  EXPECT_NE(replay.err.find("7 samples, 3 estimates"), std::string::npos) << replay.err;
}

// `sim --euroc` writes EuRoC's conventions (z-up world, the sensor's pose); importing must undo them exactly.
TEST_F(ReplayCommand, SimEurocDatasetImportsBackToTheSimulatorsTruth) {
  const fs::path dataset = dir_ / "euroc";
  ASSERT_EQ(run_imubridge("sim --scenario paper --seed 4 --duration 1 --euroc " + dataset.string()).exit_code, 0);
  const std::int64_t session = run_for_id("import euroc " + dataset.string() + " --db " + db_.string());
  const store::Store store(db_, {.read_only = true});
  std::vector<store::ReferenceRow> reference;
  store.for_each_reference(session, [&](const store::ReferenceRow& r) { reference.push_back(r); });
  std::vector<protocol::Sample> samples;
  store.for_each_sample(session, std::nullopt, [&](const protocol::Sample& s) { samples.push_back(s); });

  const auto config = sim::make_scenario("paper", 4, 1.0);
  const auto truth = sim::simulate(config);
  ASSERT_EQ(reference.size(), truth.size());
  ASSERT_EQ(samples.size(), truth.size());
  const Eigen::Vector3d& r = config.imu.pose.position_m;
  const Eigen::Matrix3d body_from_sensor = config.imu.pose.sensor_from_body.transpose();
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const auto& s = truth[i].truth;
    const Eigen::Matrix3d ned_from_body = s.attitude.toRotationMatrix();
    // The IMU's point: the mass centre's position plus the lever arm, its velocity plus omega x r.
    const Eigen::Vector3d p = s.position_ned + ned_from_body * r;
    const Eigen::Vector3d v = s.velocity_ned + ned_from_body * s.omega.cross(r);
    const auto& row = reference[i];
    EXPECT_EQ(row.t_ns, samples[i].recv_mono_ns);  // one clock for samples and reference
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR(row.position[a], p[a], 1e-12) << i;
      ASSERT_TRUE(row.velocity.has_value());  // from the file: EuRoC's ground truth has velocities
      EXPECT_NEAR((*row.velocity)[a], v[a], 1e-12) << i;
      EXPECT_NEAR(samples[i].accel[a], truth[i].measured.accel[a], 1e-3 + 1e-12) << i;  // half the import's count
    }
    const Eigen::Quaterniond q(row.quat_wxyz[0], row.quat_wxyz[1], row.quat_wxyz[2], row.quat_wxyz[3]);
    EXPECT_TRUE(q.toRotationMatrix().isApprox(ned_from_body * body_from_sensor, 1e-12)) << i;  // sensor -> NED
  }
}

// A store written here, with values chosen to test the text: NaN, -0, tiny and long numbers, absent groups, and
// an event detail that needs CSV quoting.
class ExportCommand : public ReplayCommand {
 protected:
  std::int64_t session_ = 0, run_ = 0;
  protocol::Sample with_mag_, without_mag_;
  std::vector<store::Estimate> estimates_;
  std::vector<store::ReferenceRow> reference_;

  void SetUp() override {
    ReplayCommand::SetUp();
    store::Store store(db_);
    session_ = store.begin_session({.kind = "sim", .source = "test", .config = "{}", .started_wall_ns = 1});
    const auto link = store.add_link(session_, "imu0", "imubridge", "test");
    with_mag_ = {.link_id = link,
                 .seq = 18446744073709551615u,
                 .device_time_us = 5000,
                 .recv_mono_ns = 123456789012,
                 .accel = {0.1, -0.0, 1e-300},
                 .gyro = {1.0 / 3, 2, -9.80665},
                 .mag = {21.5, -4, 43},
                 .temperature_c = 31.25,
                 .has_mag = true,
                 .has_temperature = true};
    without_mag_ = {
        .link_id = link, .seq = 1, .device_time_us = 10000, .recv_mono_ns = 2, .accel = {1, 2, 3}, .gyro = {4, 5, 6}};
    store.append_sample(session_, with_mag_);
    store.append_sample(session_, without_mag_);
    run_ = store.begin_run(session_, {.kind = "live", .params_json = "{}"});
    estimates_ = {{.link_id = link,
                   .seq = 7,
                   .t_s = 0.035,
                   .fx = -0.0,
                   .fy = 0.1 + 0.2,
                   .vx = std::nan(""),
                   .vy = std::nan(""),
                   .var_vx = std::nan(""),
                   .var_vy = 1e300}};
    store.append_estimate(run_, estimates_[0]);
    reference_ = {{.t_ns = 10, .position = {1, 2, 3}, .quat_wxyz = {1, 0, 0, 0}, .velocity = std::array{0.5, 0., 0.}},
                  {.t_ns = 20, .position = {1.5, 2, 3}, .quat_wxyz = {0, 1, 0, 0}}};
    for (const auto& row : reference_) store.append_reference(session_, row);
    store.append_event(session_, {.link_id = link,
                                  .mono_ns = 10,
                                  .wall_ns = 20,
                                  .kind = "note",
                                  .count = 1,
                                  .detail = "a, \"quoted\" word\nsecond line"});
    store.append_event(session_, {.mono_ns = 30, .wall_ns = 40, .kind = "reconnect", .count = 2, .detail = "plain"});
  }

  std::string exported(const std::string& what, const std::string& format, const std::string& time = "recorded") {
    const auto r = run_imubridge("export --db " + db_.string() + " --session " + std::to_string(session_) + " --what " +
                                 what + " --format " + format + " --time " + time);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return r.out;
  }
};

// Split one CSV line without quoted fields.
std::vector<std::string> csv_fields(const std::string& line) {
  std::vector<std::string> fields;
  std::size_t start = 0;
  for (std::size_t comma; (comma = line.find(',', start)) != std::string::npos; start = comma + 1) {
    fields.push_back(line.substr(start, comma - start));
  }
  fields.push_back(line.substr(start));
  return fields;
}

TEST_F(ExportCommand, CsvSamplesHaveAHeaderAndReadBackToTheSameDoubles) {
  const auto lines = lines_of(exported("samples", "csv"));
  ASSERT_EQ(lines.size(), 3u);
  EXPECT_EQ(lines[0], "link_id,seq,device_time_us,recv_mono_ns,ax,ay,az,gx,gy,gz,mx,my,mz,temperature_c");
  const auto a = csv_fields(lines[1]);
  ASSERT_EQ(a.size(), 14u);
  EXPECT_EQ(a[1], "18446744073709551615");  // unsigned, as the device numbered it
  EXPECT_EQ(a[3], "123456789012");
  const std::vector<double> want{0.1, -0.0, 1e-300, 1.0 / 3, 2, -9.80665, 21.5, -4, 43, 31.25};
  for (std::size_t i = 0; i < want.size(); ++i) {
    EXPECT_EQ(std::strtod(a[4 + i].c_str(), nullptr), want[i]) << a[4 + i];
  }
  EXPECT_TRUE(std::signbit(std::strtod(a[5].c_str(), nullptr)));  // -0 stays -0
  const auto b = csv_fields(lines[2]);
  ASSERT_EQ(b.size(), 14u);
  for (std::size_t i = 10; i < 14; ++i) EXPECT_EQ(b[i], "") << i;  // no magnetometer, no temperature
}

TEST_F(ExportCommand, JsonlEstimatesWriteNanAsNull) {
  const auto lines = lines_of(exported("estimates", "jsonl"));
  ASSERT_EQ(lines.size(), 1u);
  const json j = json::parse(lines[0]);
  EXPECT_EQ(j["seq"], 7);
  EXPECT_EQ(j["device_t_s"].get<double>(), 0.035);
  EXPECT_EQ(j["fy"].get<double>(), 0.1 + 0.2);
  EXPECT_TRUE(std::signbit(j["fx"].get<double>()));
  EXPECT_TRUE(j["vx"].is_null() && j["vy"].is_null() && j["var_vx"].is_null());
  EXPECT_EQ(j["var_vy"].get<double>(), 1e300);

  const auto csv = lines_of(exported("estimates", "csv"));
  ASSERT_EQ(csv.size(), 2u);
  const auto fields = csv_fields(csv[1]);
  EXPECT_EQ(fields[5], "");  // NaN
  EXPECT_EQ(fields[6], "");
}

TEST_F(ExportCommand, ReferenceWithoutVelocityIsEmptyOrNull) {
  const auto csv = lines_of(exported("reference", "csv"));
  ASSERT_EQ(csv.size(), 3u);
  EXPECT_EQ(csv[0], "mono_ns,px,py,pz,qw,qx,qy,qz,vx,vy,vz");
  EXPECT_EQ(csv_fields(csv[1])[8], "0.5");
  EXPECT_EQ(csv_fields(csv[2])[8], "");
  const auto jsonl = lines_of(exported("reference", "jsonl"));
  ASSERT_EQ(jsonl.size(), 2u);
  EXPECT_EQ(json::parse(jsonl[0])["vx"].get<double>(), 0.5);
  EXPECT_TRUE(json::parse(jsonl[1])["vx"].is_null());
  EXPECT_EQ(json::parse(jsonl[1])["px"].get<double>(), 1.5);
}

TEST_F(ExportCommand, EventsQuoteTextAsRfc4180SaysAndKeepSessionEventsApart) {
  const std::string link = std::to_string(with_mag_.link_id);
  EXPECT_EQ(exported("events", "csv"), "link_id,mono_ns,wall_ns,kind,count,detail\n" + link +
                                           ",10,20,note,1,\"a, \"\"quoted\"\" word\nsecond line\"\n"
                                           ",30,40,reconnect,2,plain\n");
  const auto jsonl = lines_of(exported("events", "jsonl"));
  ASSERT_EQ(jsonl.size(), 2u);
  EXPECT_EQ(json::parse(jsonl[0])["detail"], "a, \"quoted\" word\nsecond line");
  EXPECT_TRUE(json::parse(jsonl[1])["link_id"].is_null());
}

// Session time by default, as identify, diagnose and import speak: samples and estimates from their link's first
// sample on the IMU's clock (5000 us here), reference and events from the first sample's arrival (123456789012 ns).
TEST_F(ExportCommand, SessionTimeIsTheDefaultAndSaysSo) {
  const auto r =
      run_imubridge("export --db " + db_.string() + " --session " + std::to_string(session_) + " --what samples");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto samples = lines_of(r.out);
  ASSERT_EQ(samples.size(), 3u);
  EXPECT_EQ(samples[0], "link_id,seq,session_t_s,ax,ay,az,gx,gy,gz,mx,my,mz,temperature_c");
  EXPECT_EQ(csv_fields(samples[1])[2], "0");
  EXPECT_EQ(csv_fields(samples[2])[2], "0.005");  // device time 10000 us
  EXPECT_NE(r.err.find("times: session time (session_t_s: s since the first sample)"), std::string::npos) << r.err;
  const auto estimates = lines_of(exported("estimates", "jsonl", "session"));
  ASSERT_EQ(estimates.size(), 1u);
  EXPECT_EQ(json::parse(estimates[0])["session_t_s"].get<double>(), 0.03);  // 0.035 s on the IMU's clock
  const auto reference = lines_of(exported("reference", "csv", "session"));
  EXPECT_EQ(reference[0], "session_t_s,px,py,pz,qw,qx,qy,qz,vx,vy,vz");
  EXPECT_EQ(std::strtod(csv_fields(reference[1])[0].c_str(), nullptr), (10 - 123456789012) / 1e9);
  const auto events = lines_of(exported("events", "csv", "session"));
  EXPECT_EQ(events[0], "link_id,session_t_s,wall_ns,kind,count,detail");
  const auto recorded = run_imubridge("export --db " + db_.string() + " --session " + std::to_string(session_) +
                                      " --what samples --time recorded");
  EXPECT_NE(recorded.err.find("times: the store's clocks"), std::string::npos) << recorded.err;
}

TEST_F(ExportCommand, SessionTimeOfASessionWithoutSamplesIsRefusedWithTheRemedy) {
  std::int64_t empty = 0;
  {
    store::Store store(db_);
    empty = store.begin_session({.kind = "sim", .config = "{}"});
  }
  const auto r =
      run_imubridge("export --db " + db_.string() + " --session " + std::to_string(empty) + " --what events");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("has no samples, so no session time"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--time recorded"), std::string::npos) << r.err;
  EXPECT_EQ(run_imubridge("export --db " + db_.string() + " --session " + std::to_string(empty) +
                          " --what events --time recorded")
                .exit_code,
            0);
}

// A failed export leaves a good earlier one as it was (issue 28: it was emptied), and writes nothing new.
TEST_F(ExportCommand, AFailedExportLeavesAnExistingFileUntouched) {
  const fs::path out = dir_ / "est.csv";
  const std::string base = "export --db " + db_.string() + " --out " + out.string();
  const auto good = run_imubridge(base + " --session " + std::to_string(session_) + " --what estimates");
  ASSERT_EQ(good.exit_code, 0) << good.err;
  const std::string before = slurp(out);
  ASSERT_EQ(lines_of(before).size(), 2u);
  for (const std::string& args : {base + " --session " + std::to_string(session_) + " --what estimates --run 2",
                                  base + " --session 99 --what estimates"}) {
    const auto r = run_imubridge(args);
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_EQ(slurp(out), before) << args;
  }
  for (const auto& entry : fs::directory_iterator(dir_)) {
    EXPECT_NE(entry.path().filename().string().rfind(".est.csv", 0), 0u) << "a temporary file left: " << entry.path();
  }
  const fs::path fresh = dir_ / "fresh.csv";
  EXPECT_EQ(run_imubridge("export --db " + db_.string() + " --out " + fresh.string() + " --session 99 --what samples")
                .exit_code,
            2);
  EXPECT_FALSE(fs::exists(fresh));
}

// No empty store is left behind by an import that fails, and a store without its folder is a usage error.
TEST_F(ReplayCommand, AFailedImportLeavesNoStoreAndAMissingFolderIsAUsageError) {
  const fs::path db = dir_ / "new.db";
  for (const char* format : {"ulog", "tlog", "euroc"}) {
    const auto r =
        run_imubridge(std::string("import ") + format + " " + (dir_ / "unreadable").string() + " --db " + db.string());
    EXPECT_EQ(r.exit_code, 2) << format << ": " << r.err;
    EXPECT_EQ(count_lines(r.err), 1) << r.err;
    EXPECT_FALSE(fs::exists(db)) << format;
    EXPECT_FALSE(fs::exists(db.string() + "-wal")) << format;
  }
  const auto r =
      run_imubridge("import ulog " + std::string(IMUBRIDGE_SOURCE_DIR) + "/tests/data/ulog/sample_log_small.ulg" +
                    " --db " + (dir_ / "no_folder" / "x.db").string());
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(count_lines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("no folder " + (dir_ / "no_folder").string()), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("give --db FILE"), std::string::npos) << r.err;
}

TEST_F(ExportCommand, OutWritesAFileInsteadOfStdout) {
  const fs::path out = dir_ / "samples.jsonl";
  const auto r = run_imubridge("export --db " + db_.string() + " --session " + std::to_string(session_) +
                               " --what samples --format jsonl --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out, "");
  EXPECT_EQ(lines_of(slurp(out)).size(), 2u);
}

TEST_F(ExportCommand, MistakesGetOneLineErrors) {
  const std::string db = " --db " + db_.string();
  const std::string session = " --session " + std::to_string(session_);
  const fs::path missing = dir_ / "missing.db";
  struct Case {
    std::string args, message;
  };
  {
    store::Store store(db_);
    store.begin_run(session_, {.kind = "replay"});  // now the session has two runs
  }
  for (const Case& c : std::vector<Case>{
           {"export --db " + missing.string() + session + " --what samples", "missing.db: no such file"},
           {"replay --db " + missing.string() + session, "missing.db: no such file"},
           {"export" + db + " --session 99 --what samples", "no session 99 in the store"},
           {"replay" + db + " --session 99", "no session 99 in the store"},
           {"export" + db + session + " --what estimates --run 42", "has no run 42"},
           {"export" + db + session + " --what estimates", "choose one with --run"},
           {"export" + db + session + " --what samples --run " + std::to_string(run_), "--run selects estimates"},
           {"replay" + db + session + " --speed fast", "--speed"},
           {"import euroc " + (dir_ / "nowhere").string() + db, "no such file"},
       }) {
    const auto r = run_imubridge(c.args);
    EXPECT_EQ(r.exit_code, 2) << c.args << "\n" << r.err;
    EXPECT_EQ(count_lines(r.err), 1) << c.args << "\n" << r.err;
    EXPECT_NE(r.err.find(c.message), std::string::npos) << c.args << "\n" << r.err;
    EXPECT_EQ(r.out, "") << c.args;
  }
  EXPECT_FALSE(fs::exists(missing)) << "a reader created the store it could not find";
}

}  // namespace
}  // namespace imubridge::test
