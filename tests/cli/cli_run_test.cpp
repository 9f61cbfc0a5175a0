// `imubridge run` end to end, as a user runs it: frames written into a pseudo-terminal, the daemon reading its slave
// through a symlink, and the database checked afterwards. Storage limits: cli_run_storage_test.cpp.
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/un.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <random>

#include "pipeline/estimation_stage.hpp"
#include "protocol/imu_frame.hpp"
#include "tests/support/cli_run_harness.hpp"

namespace imubridge::test {
namespace {

// One link named "imu" on a pty symlinked at dir/tty, recorded into dir/run.db, reconnecting quickly.
class RunTest : public ::testing::Test {
 protected:
  void SetUp() override { write_config(""); }

  void write_config(const std::string& extra_tables, int reconnect_min_ms = 10, int reconnect_max_ms = 50) {
    std::ofstream(config_) << "stats_interval_s = 3600\n"
                           << extra_tables << "[store]\npath = \"" << db_.string() << "\"\nmin_free_mib = 0\n"
                           << "[[link]]\nname = \"imu\"\ndevice = \"" << tty_.string() << "\"\n"
                           << "protocol = \"imubridge\"\nreconnect_min_ms = " << reconnect_min_ms
                           << "\nreconnect_max_ms = " << reconnect_max_ms << "\n";
  }
  void start(const SpawnOptions& options = {}) {
    daemon_ = std::make_unique<Process>(std::vector<std::string>{"run", "--config", config_.string()}, dir_ / "stderr",
                                        options);
  }
  // Ends the daemon as systemd does and opens what it recorded.
  void stop() {
    daemon_->signal(SIGTERM);
    ASSERT_EQ(daemon_->wait(), 0) << daemon_->log();
  }

  TempDir dir_;
  fs::path config_ = dir_ / "imubridge.toml", db_ = dir_ / "run.db", tty_ = dir_ / "tty";
  std::unique_ptr<Process> daemon_;
};

TEST_F(RunTest, EveryFrameIsStoredAndEstimatedAndCounted) {
  constexpr std::size_t kFrames = 600;
  const auto frames = simulated_frames(kFrames);
  cli::PtyPair pty(tty_);
  start();
  ASSERT_TRUE(daemon_->wait_for_log("link 'imu': reading")) << daemon_->log();
  write_paced(pty, frames);
  ASSERT_TRUE(wait_for_samples(db_, kFrames)) << daemon_->log();
  daemon_->signal(SIGUSR1);
  ASSERT_TRUE(daemon_->wait_for_log("stats {")) << daemon_->log();
  stop();

  const store::Store store(db_, {.read_only = true});
  const auto sessions = store.sessions();
  ASSERT_EQ(sessions.size(), 1u);
  const auto& session = sessions[0];
  EXPECT_EQ(session.info.kind, "live");
  EXPECT_TRUE(session.ended_wall_ns.has_value()) << "SIGTERM ends the session";
  const auto links = store.links(session.id);
  ASSERT_EQ(links.size(), 1u);
  EXPECT_EQ(links[0].name, "imu");

  std::vector<std::uint8_t> received;
  store.for_each_chunk(session.id, std::nullopt,
                       [&](const store::Chunk& c) { received.insert(received.end(), c.bytes.begin(), c.bytes.end()); });
  std::vector<std::uint8_t> sent;
  for (const auto& f : frames) sent.insert(sent.end(), f.begin(), f.end());
  EXPECT_EQ(received, sent) << "the raw chunks are the byte stream, exactly";

  std::vector<std::uint64_t> seqs;
  store.for_each_sample(session.id, std::nullopt, [&](const protocol::Sample& s) { seqs.push_back(s.seq); });
  ASSERT_EQ(seqs.size(), kFrames);
  for (std::size_t i = 0; i < kFrames; ++i) ASSERT_EQ(seqs[i], i);

  // The estimator's differentiator is centred delay samples back: the first `delay` samples complete no window and
  // the last `delay` are still waiting for theirs when the stream ends.
  const int delay = pipeline::EstimationStage(estimator::ModelParams{}).delay_samples();
  const auto runs = store.runs(session.id);
  ASSERT_EQ(runs.size(), 1u);
  EXPECT_EQ(runs[0].info.kind, "live");
  std::vector<std::uint64_t> estimated;
  store.for_each_estimate(runs[0].id, [&](const store::Estimate& e) {
    estimated.push_back(e.seq);
    EXPECT_TRUE(std::isfinite(e.fx) && std::isfinite(e.fy));
    EXPECT_TRUE(std::isnan(e.vx)) << "no parameters: no drag to invert, velocity is NULL";
  });
  ASSERT_EQ(estimated.size(), kFrames - 2 * delay);
  for (std::size_t i = 0; i < estimated.size(); ++i) ASSERT_EQ(estimated[i], i + delay);

  const auto events = store.events(session.id);
  const auto counters = std::find_if(events.begin(), events.end(), [](const auto& e) { return e.kind == "counters"; });
  ASSERT_NE(counters, events.end());
  const auto decoder = nlohmann::json::parse(counters->detail).at("imubridge");
  EXPECT_EQ(decoder.at("bytes_in"), sent.size());
  EXPECT_EQ(decoder.at("frames_out"), kFrames);
  EXPECT_EQ(decoder.at("bytes_discarded"), 0);
  EXPECT_EQ(decoder.at("frames_lost"), 0);
  const auto totals = event_totals(store, session.id);
  EXPECT_EQ(totals.count("sequence_gap") + totals.count("crc_failure") + totals.count("bytes_discarded"), 0u);
  EXPECT_EQ(totals.at("connected"), 1);
}

// The programs a user runs, end to end: `imubridge sim --pty` streams a flight, `imubridge run` records it. Every
// byte the simulator wrote is stored, the last ones too (the simulator waits for its reader before closing).
TEST_F(RunTest, TheSimulatorsStreamOverAPtyIsStoredWhole) {
  const std::string flight = "sim --scenario paper --seed 4 --duration 1 --rate 500";
  const auto file = run_imubridge(flight + " --file " + (dir_ / "flight.bin").string());  // the same bytes, as a file
  ASSERT_EQ(file.exit_code, 0) << file.err;
  const std::string sent = slurp(dir_ / "flight.bin");
  start();  // the device appears when the simulator starts: the daemon waits for it
  ASSERT_TRUE(daemon_->wait_for_log("cannot open")) << daemon_->log();
  const auto vehicle = run_imubridge(flight + " --speed 2 --pty " + tty_.string());
  ASSERT_EQ(vehicle.exit_code, 0) << vehicle.err;
  EXPECT_EQ(vehicle.err.find("nobody was reading"), std::string::npos) << vehicle.err;
  ASSERT_TRUE(wait_for_samples(db_, 500)) << daemon_->log();
  stop();

  const store::Store store(db_, {.read_only = true});
  const std::int64_t session = store.sessions().at(0).id;
  std::string received;
  store.for_each_chunk(session, std::nullopt,
                       [&](const store::Chunk& c) { received.append(c.bytes.begin(), c.bytes.end()); });
  EXPECT_EQ(received.size(), sent.size());
  EXPECT_EQ(received, sent);
  std::vector<std::uint64_t> seqs;
  store.for_each_sample(session, std::nullopt, [&](const protocol::Sample& s) { seqs.push_back(s.seq); });
  ASSERT_EQ(seqs.size(), 500u);
  for (std::size_t i = 0; i < seqs.size(); ++i) ASSERT_EQ(seqs[i], i);
  std::size_t estimates = 0;
  store.for_each_estimate(store.runs(session).at(0).id, [&](const store::Estimate&) { ++estimates; });
  EXPECT_EQ(estimates, seqs.size() - 2 * pipeline::EstimationStage(estimator::ModelParams{}).delay_samples());
}

TEST_F(RunTest, GarbageAndBitFlipsLoseOnlyTheDamagedFramesAndCountThemExactly) {
  constexpr std::size_t kFrames = 400;
  auto frames = simulated_frames(kFrames);
  std::mt19937 rng(5);
  std::vector<std::vector<std::uint8_t>> line;
  std::size_t garbage = 0, flipped = 0;
  for (std::size_t i = 0; i < kFrames; ++i) {
    if (i % 25 == 7) {
      // A burst of noise without the first sync byte: it can start no frame, so every byte of it is discarded.
      std::vector<std::uint8_t> noise(1 + rng() % 60);
      for (auto& b : noise) do
          b = static_cast<std::uint8_t>(rng());
        while (b == protocol::imu::kSync0);
      garbage += noise.size();
      line.push_back(std::move(noise));
    }
    if (i % 40 == 13) {
      // One bit of the payload: only the CRC can tell, and it always does for a single bit.
      const std::size_t at = protocol::imu::kHeaderSize + rng() % protocol::imu::kImuSamplePayloadSize;
      frames[i][at] ^= static_cast<std::uint8_t>(1u << (rng() % 8));
      ++flipped;
    }
    line.push_back(frames[i]);
  }
  const std::size_t frame_size = frames[0].size();
  cli::PtyPair pty(tty_);
  start();
  ASSERT_TRUE(daemon_->wait_for_log("link 'imu': reading")) << daemon_->log();
  write_paced(pty, line);
  ASSERT_TRUE(wait_for_samples(db_, kFrames - flipped)) << daemon_->log();
  stop();

  const store::Store store(db_, {.read_only = true});
  const std::int64_t session = store.sessions().at(0).id;
  std::vector<std::uint64_t> seqs;
  store.for_each_sample(session, std::nullopt, [&](const protocol::Sample& s) { seqs.push_back(s.seq); });
  std::vector<std::uint64_t> expected;
  for (std::size_t i = 0; i < kFrames; ++i) {
    if (i % 40 != 13) expected.push_back(i);
  }
  EXPECT_EQ(seqs, expected) << "every undamaged frame arrives, in order";
  const auto totals = event_totals(store, session);
  EXPECT_EQ(totals.at("crc_failure"), static_cast<std::int64_t>(flipped));
  EXPECT_EQ(totals.at("sequence_gap"), static_cast<std::int64_t>(flipped)) << "frames missing by sequence number";
  EXPECT_EQ(totals.at("bytes_discarded"), static_cast<std::int64_t>(garbage + flipped * frame_size));
}

TEST_F(RunTest, AnUnpluggedDeviceIsReconnectedAndRecordedInTheSameSession) {
  constexpr std::size_t kFrames = 500, kUnplugAt = 200, kLostWhileUnplugged = 30;
  const auto frames = simulated_frames(kFrames);
  const std::vector<std::vector<std::uint8_t>> before(frames.begin(), frames.begin() + kUnplugAt);
  const std::vector<std::vector<std::uint8_t>> after(frames.begin() + kUnplugAt + kLostWhileUnplugged, frames.end());
  auto pty = std::make_unique<cli::PtyPair>(tty_);
  start();
  ASSERT_TRUE(daemon_->wait_for_log("link 'imu': reading")) << daemon_->log();
  write_paced(*pty, before);
  ASSERT_TRUE(wait_for_samples(db_, kUnplugAt)) << daemon_->log();
  pty.reset();  // the device vanishes: master closed, symlink gone
  ASSERT_TRUE(daemon_->wait_for_log("lost /")) << daemon_->log();
  pty = std::make_unique<cli::PtyPair>(tty_);  // it comes back as another pty, at the same path
  ASSERT_TRUE(daemon_->wait_for_log("reconnected to")) << daemon_->log();
  write_paced(*pty, after);
  ASSERT_TRUE(wait_for_samples(db_, kUnplugAt + after.size())) << daemon_->log();
  stop();

  EXPECT_EQ(count_of(daemon_->log(), "lost /"), 1) << "one outage, one line, however many attempts:\n"
                                                   << daemon_->log();
  const store::Store store(db_, {.read_only = true});
  ASSERT_EQ(store.sessions().size(), 1u);
  const std::int64_t session = store.sessions()[0].id;
  ASSERT_EQ(store.links(session).size(), 1u) << "the same store link before and after";
  const auto totals = event_totals(store, session);
  EXPECT_EQ(totals.at("link_lost"), 1);
  EXPECT_EQ(totals.at("reconnect"), 1);
  EXPECT_EQ(totals.at("sequence_gap"), static_cast<std::int64_t>(kLostWhileUnplugged));
  std::vector<std::uint64_t> seqs;
  store.for_each_sample(session, std::nullopt, [&](const protocol::Sample& s) { seqs.push_back(s.seq); });
  ASSERT_EQ(seqs.size(), kFrames - kLostWhileUnplugged);
  EXPECT_EQ(seqs[kUnplugAt - 1], kUnplugAt - 1);
  EXPECT_EQ(seqs[kUnplugAt], kUnplugAt + kLostWhileUnplugged);
}

// The device reboots while unplugged: it comes back at the same path with its frame counter and clock from zero.
// The backoff is 2 s and more, so only the watch on the link's directory can reconnect within a second.
TEST_F(RunTest, ADeviceThatRestartsIsReconnectedAtOnceAndEstimatedOnItsNewClock) {
  write_config("", 2000, 5000);
  constexpr std::size_t kBefore = 400, kAfter = 300;
  auto pty = std::make_unique<cli::PtyPair>(tty_);
  start();
  ASSERT_TRUE(daemon_->wait_for_log("link 'imu': reading")) << daemon_->log();
  write_paced(*pty, simulated_frames(kBefore, 3));
  ASSERT_TRUE(wait_for_samples(db_, kBefore)) << daemon_->log();
  pty.reset();
  ASSERT_TRUE(daemon_->wait_for_log("lost /")) << daemon_->log();
  std::this_thread::sleep_for(300ms);  // the first retry is 2 s away
  timespec appeared{};
  ::clock_gettime(CLOCK_MONOTONIC, &appeared);  // the store's recv_mono_ns clock
  pty = std::make_unique<cli::PtyPair>(tty_);
  write_paced(*pty, simulated_frames(kAfter, 5));  // numbered from 0 again, its clock from 0 again
  ASSERT_TRUE(wait_for_samples(db_, kBefore + kAfter)) << daemon_->log();
  stop();

  const store::Store store(db_, {.read_only = true});
  const std::int64_t session = store.sessions().at(0).id;
  std::vector<protocol::Sample> samples;
  store.for_each_sample(session, std::nullopt, [&](const protocol::Sample& s) { samples.push_back(s); });
  ASSERT_EQ(samples.size(), kBefore + kAfter);
  for (std::size_t i = 0; i < samples.size(); ++i) ASSERT_EQ(samples[i].seq, i) << "no jump at the restart";
  const double reconnect_s =
      static_cast<double>(samples[kBefore].recv_mono_ns - (appeared.tv_sec * 1'000'000'000LL + appeared.tv_nsec)) *
      1e-9;
  EXPECT_LT(reconnect_s, 1.0) << "from the device appearing to its first sample";
  const auto totals = event_totals(store, session);
  EXPECT_EQ(totals.at("device_restart"), 1);
  EXPECT_EQ(totals.count("sequence_gap"), 0u) << "nothing was lost: the new stream starts at 0";
  EXPECT_EQ(count_of(daemon_->log(), "the device restarted"), 1) << daemon_->log();
  // Every sample gets an estimate but those the differentiator's centred window cannot reach: its first and last
  // delay_samples() on each clock.
  std::size_t before = 0, after = 0;
  store.for_each_estimate(store.runs(session).at(0).id,
                          [&](const store::Estimate& e) { ++(e.seq < kBefore ? before : after); });
  const std::size_t edge = 2 * pipeline::EstimationStage(estimator::ModelParams{}).delay_samples();
  EXPECT_EQ(before, kBefore - edge);
  EXPECT_EQ(after, kAfter - edge);
}

// A feeder killed with -9 leaves the link's symlink naming its freed pty. Whoever gets that pty next (a terminal,
// say) is not the device: the daemon waits for the symlink to be pointed anew.
TEST_F(RunTest, AFreedPtyTheSymlinkStillNamesIsNotRead) {
  auto feeder = std::make_unique<cli::PtyPair>(dir_ / "feeder");
  fs::create_symlink(feeder->slave_name(), tty_);
  const std::string freed = feeder->slave_name();
  start();
  ASSERT_TRUE(daemon_->wait_for_log("link 'imu': reading")) << daemon_->log();
  write_paced(*feeder, simulated_frames(50));
  ASSERT_TRUE(wait_for_samples(db_, 50)) << daemon_->log();
  feeder.reset();  // its own symlink goes, ours stays
  ASSERT_TRUE(daemon_->wait_for_log("lost /")) << daemon_->log();
  // The kernel gives out the lowest free pty number: hold pairs until one is the freed pty.
  std::vector<std::unique_ptr<cli::PtyPair>> others;
  for (int i = 0; i < 64 && (others.empty() || others.back()->slave_name() != freed); ++i)
    others.push_back(std::make_unique<cli::PtyPair>(dir_ / ("other" + std::to_string(i))));
  if (others.back()->slave_name() != freed) GTEST_SKIP() << freed << " was taken by another process";
  cli::PtyPair& stranger = *others.back();
  ASSERT_TRUE(daemon_->wait_for_log("still names the tty")) << daemon_->log();
  write_paced(stranger, simulated_frames(20, 7));
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(committed_samples(db_).size(), 50u) << "nothing from the stranger's pty";

  fs::remove(tty_);  // pointed anew, at the same pty: now it is the device
  fs::create_symlink(stranger.slave_name(), tty_);
  ASSERT_TRUE(daemon_->wait_for_log("reconnected to")) << daemon_->log();
  write_paced(stranger, simulated_frames(20, 7));
  EXPECT_TRUE(wait_for_samples(db_, 70)) << daemon_->log();
  stop();
}

// A tty that is some session's controlling terminal is a person's terminal, whatever the link names.
TEST_F(RunTest, AnotherSessionsTerminalIsNeverRead) {
  cli::PtyPair terminal(dir_ / "terminal");
  const pid_t shell = ::fork();
  if (shell == 0) {
    ::setsid();
    // A session leader without a terminal acquires the first tty it opens without O_NOCTTY.
    if (::open(terminal.slave_name().c_str(), O_RDWR) < 0) ::_exit(1);
    ::pause();
    ::_exit(0);
  }
  ASSERT_GT(shell, 0);
  fs::create_symlink(terminal.slave_name(), tty_);
  start();
  EXPECT_TRUE(daemon_->wait_for_log("controlling terminal of process " + std::to_string(shell))) << daemon_->log();
  write_paced(terminal, simulated_frames(20));
  std::this_thread::sleep_for(200ms);
  EXPECT_EQ(committed_samples(db_).size(), 0u);
  stop();
  ::kill(shell, SIGKILL);
  ::waitpid(shell, nullptr, 0);
}

TEST_F(RunTest, KillMinus9KeepsEverythingCommittedBeforeIt) {
  const auto frames = simulated_frames(1200);
  cli::PtyPair pty(tty_);
  start();
  ASSERT_TRUE(daemon_->wait_for_log("link 'imu': reading")) << daemon_->log();
  write_paced(pty, {frames.begin(), frames.begin() + 600});
  ASSERT_TRUE(wait_for_samples(db_, 300));
  const auto seen = committed_samples(db_);                // what a reader saw before the kill
  write_paced(pty, {frames.begin() + 600, frames.end()});  // mid-stream: the daemon has an open batch
  daemon_->signal(SIGKILL);
  ASSERT_EQ(daemon_->wait(), -SIGKILL);

  EXPECT_EQ(integrity_check(db_), "ok");
  const auto kept = committed_samples(db_);
  ASSERT_GE(kept.size(), seen.size());
  for (std::size_t i = 0; i < seen.size(); ++i) {
    ASSERT_EQ(kept[i].seq, seen[i].seq);
    ASSERT_EQ(kept[i].accel, seen[i].accel);
  }
}

TEST_F(RunTest, AMissingDeviceIsWaitedForNotFatal) {
  start();
  ASSERT_TRUE(daemon_->wait_for_log("cannot open")) << daemon_->log();
  std::this_thread::sleep_for(200ms);  // several attempts at 10..50 ms: still one line
  cli::PtyPair pty(tty_);
  ASSERT_TRUE(daemon_->wait_for_log("link 'imu': reading")) << daemon_->log();
  write_paced(pty, simulated_frames(50));
  ASSERT_TRUE(wait_for_samples(db_, 50));
  stop();
  EXPECT_EQ(count_of(daemon_->log(), "cannot open"), 1) << daemon_->log();
}

TEST_F(RunTest, SighupMovesThePlotJugglerOutput) {
  const auto open_udp = [] {
    const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK, 0);
    sockaddr_in address{.sin_family = AF_INET, .sin_port = 0, .sin_addr = {htonl(INADDR_LOOPBACK)}, .sin_zero = {}};
    ::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof address);
    socklen_t size = sizeof address;
    ::getsockname(fd, reinterpret_cast<sockaddr*>(&address), &size);
    return std::pair{fd, ntohs(address.sin_port)};
  };
  const auto received = [](int fd) {
    std::vector<nlohmann::json> messages;
    char buffer[4096];
    for (ssize_t n; (n = ::recv(fd, buffer, sizeof buffer, 0)) > 0;) {
      messages.push_back(nlohmann::json::parse(std::string_view(buffer, static_cast<std::size_t>(n))));
    }
    return messages;
  };
  const auto [first, first_port] = open_udp();
  const auto [second, second_port] = open_udp();
  const auto outputs_to = [&](std::uint16_t port) {
    write_config("[outputs]\nplotjuggler = \"udp://127.0.0.1:" + std::to_string(port) + "\"\n");
  };
  const auto frames = simulated_frames(100);
  outputs_to(first_port);
  cli::PtyPair pty(tty_);
  start();
  ASSERT_TRUE(daemon_->wait_for_log("link 'imu': reading")) << daemon_->log();
  write_paced(pty, {frames.begin(), frames.begin() + 50});
  ASSERT_TRUE(wait_for_samples(db_, 50));
  outputs_to(second_port);
  daemon_->signal(SIGHUP);
  ASSERT_TRUE(daemon_->wait_for_log("SIGHUP: reloaded")) << daemon_->log();
  write_paced(pty, {frames.begin() + 50, frames.end()});
  ASSERT_TRUE(wait_for_samples(db_, 100));
  stop();

  const auto before = received(first);
  const auto after = received(second);
  ::close(first);
  ::close(second);
  ASSERT_FALSE(before.empty());
  ASSERT_FALSE(after.empty());
  // PlotJuggler's datagrams carry each link's sample under the link's name (docs/outputs.md).
  EXPECT_LT(before.back().at("imu").at("seq").get<std::uint64_t>(), 50u)
      << "nothing after the reload went to the old port";
  EXPECT_GE(after.front().at("imu").at("seq").get<std::uint64_t>(), 50u);
  EXPECT_EQ(after.back().at("imu").at("seq"), 99);
}

// A ground-control station on a UDP bridge gets the link's bytes and its replies reach the vehicle; velocity
// feedback reaches it too; and everything sent to the vehicle is recorded as tx chunks, byte for byte.
TEST_F(RunTest, BridgeAndFeedbackBytesReachTheVehicleAndAreRecorded) {
  const int station = ::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK, 0);
  sockaddr_in address{.sin_family = AF_INET, .sin_port = 0, .sin_addr = {htonl(INADDR_LOOPBACK)}, .sin_zero = {}};
  ASSERT_EQ(::bind(station, reinterpret_cast<sockaddr*>(&address), sizeof address), 0);
  socklen_t size = sizeof address;
  ::getsockname(station, reinterpret_cast<sockaddr*>(&address), &size);
  estimator::ModelParams params;  // drag, so that velocities are estimated and fed back
  params.full.drag_quadratic = {sim::kPaperMu, sim::kPaperMu};
  std::ofstream(dir_ / "params.json") << nlohmann::json(params).dump();
  std::ofstream(config_) << "params = \"" << (dir_ / "params.json").string() << "\"\n"
                         << "[store]\npath = \"" << db_.string() << "\"\nmin_free_mib = 0\n"
                         << "[[link]]\nname = \"imu\"\ndevice = \"" << tty_.string() << "\"\n"
                         << "bridge = [\"udp://127.0.0.1:" << ntohs(address.sin_port) << "\"]\n"
                         << "[link.feedback]\nrate_hz = 1000\n";
  const auto frames = simulated_frames(400);
  cli::PtyPair pty(tty_);
  start();
  ASSERT_TRUE(daemon_->wait_for_log("link 'imu': reading")) << daemon_->log();
  write_paced(pty, frames);
  ASSERT_TRUE(wait_for_samples(db_, frames.size())) << daemon_->log();

  std::vector<std::uint8_t> at_station;
  sockaddr_in bridge{};
  ASSERT_TRUE(eventually([&] {
    std::uint8_t buffer[4096];
    socklen_t length = sizeof bridge;
    for (ssize_t n;
         (n = ::recvfrom(station, buffer, sizeof buffer, 0, reinterpret_cast<sockaddr*>(&bridge), &length)) > 0;) {
      at_station.insert(at_station.end(), buffer, buffer + n);
    }
    return at_station.size() >= frames.size() * frames[0].size();
  }));
  const std::string command = "a ground station's command";
  ::sendto(station, command.data(), command.size(), 0, reinterpret_cast<sockaddr*>(&bridge), sizeof bridge);
  std::vector<std::uint8_t> at_vehicle;
  ASSERT_TRUE(eventually([&] {
    std::uint8_t buffer[4096];
    for (ssize_t n; (n = ::read(pty.master_fd(), buffer, sizeof buffer)) > 0;) {
      at_vehicle.insert(at_vehicle.end(), buffer, buffer + n);
    }
    return std::search(at_vehicle.begin(), at_vehicle.end(), command.begin(), command.end()) != at_vehicle.end();
  }));
  stop();
  ::close(station);

  std::vector<std::uint8_t> sent;
  for (const auto& f : frames) sent.insert(sent.end(), f.begin(), f.end());
  EXPECT_EQ(at_station, sent) << "the station gets the link's bytes as they came";
  std::vector<protocol::imu::Frame> fed_back;
  protocol::imu::Decoder decoder;
  decoder.feed(at_vehicle, fed_back);
  ASSERT_FALSE(fed_back.empty()) << "velocity feedback frames";
  for (const auto& frame : fed_back) EXPECT_EQ(frame.type(), protocol::imu::MsgType::velocity_estimate);
  const store::Store store(db_, {.read_only = true});
  std::vector<std::uint8_t> recorded_tx;
  store.for_each_chunk(store.sessions().at(0).id, std::nullopt, [&](const store::Chunk& c) {
    if (c.direction == store::Direction::tx) recorded_tx.insert(recorded_tx.end(), c.bytes.begin(), c.bytes.end());
  });
  EXPECT_EQ(recorded_tx, at_vehicle) << "every byte written to the vehicle is in the store, in order";
}

TEST_F(RunTest, SystemdHearsReadyStatusWatchdogAndStopping) {
  const fs::path socket_path = dir_ / "notify";
  const int fd = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_NONBLOCK, 0);
  sockaddr_un address{.sun_family = AF_UNIX, .sun_path = {}};
  socket_path.string().copy(address.sun_path, sizeof address.sun_path - 1);
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof address), 0);
  std::string heard;
  const auto listen_for = [&](const std::string& what) {
    return eventually([&] {
      char buffer[4096];
      for (ssize_t n; (n = ::recv(fd, buffer, sizeof buffer, 0)) > 0;) heard.append(buffer, n).append("\n");
      return heard.find(what) != std::string::npos;
    });
  };
  cli::PtyPair pty(tty_);
  start({.env = {{"NOTIFY_SOCKET", socket_path.string()}, {"WATCHDOG_USEC", "100000"}}, .file_size_limit = {}});
  ASSERT_TRUE(listen_for("READY=1")) << heard;
  EXPECT_NE(heard.find("STATUS=recording session 1 into " + db_.string()), std::string::npos) << heard;
  EXPECT_TRUE(listen_for("WATCHDOG=1")) << heard;
  stop();
  EXPECT_TRUE(listen_for("STOPPING=1")) << heard;
  ::close(fd);
}

TEST(RunCli, ConfigurationMistakesGiveOneLineAndExitCode2) {
  TempDir dir;
  const auto run_with = [&](const std::string& toml, const std::string& more = "") {
    std::ofstream(dir / "bad.toml") << toml;
    return run_imubridge("run --config " + (dir / "bad.toml").string() + " " + more);
  };
  const std::string link = "[[link]]\nname = \"imu\"\ndevice = \"/dev/null\"\n";

  auto r = run_with(link + "baudrate = 9600\n");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.err, "imubridge run: error: " + (dir / "bad.toml").string() +
                       ":4: unknown key 'link[0].baudrate' (did you mean 'baud'?)\n");
  r = run_with(link + "protocol = \"ubx\"\n");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(count_lines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("'link[0].protocol'"), std::string::npos) << r.err;
  r = run_with("[store]\npath = \"x.db\"\n");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("no links configured"), std::string::npos) << r.err;
  r = run_with("[store\n");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(count_lines(r.err), 1) << r.err;
  r = run_with("", "--link imu=/dev/null");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--link 'imu=/dev/null'"), std::string::npos) << r.err;

  r = run_imubridge("run --config " + (dir / "missing.toml").string());
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("missing.toml: cannot read"), std::string::npos) << r.err;
  r = run_imubridge("run --link imu=/dev/null:imubridge --db " + (dir / "x.db").string() + " --params " +
                    (dir / "missing.json").string());
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(count_lines(r.err), 1) << r.err;
}

// A baud rate no serial port takes is a configuration mistake, found before the daemon starts retrying the port.
TEST(RunCli, ABadBaudRateIsRefusedAtStartNamingIt) {
  TempDir dir;
  const std::string db = " --db " + (dir / "x.db").string();
  for (const char* rate : {"12345", "100000000", "-5", "0"}) {
    const auto r = run_imubridge(std::string("run --link imu=/dev/ttyUSB0:imubridge:") + rate + db);
    EXPECT_EQ(r.exit_code, 2) << rate;
    EXPECT_EQ(count_lines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(std::string("baud rate ") + rate + " is not one a serial port can be set to"),
              std::string::npos)
        << r.err;
  }
  std::ofstream(dir / "imubridge.toml") << "[[link]]\nname = \"imu\"\ndevice = \"/dev/ttyUSB0\"\nbaud = 1\n";
  const auto r = run_imubridge("run --config " + (dir / "imubridge.toml").string() + db);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(count_lines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find(":4: 'link[0].baud' baud rate 1 is not one"), std::string::npos) << r.err;
}

TEST(RunCli, ADirectoryGivenForAFileIsCalledOne) {
  TempDir dir;
  auto r = run_imubridge("run --config " + dir.path().string());
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.err, "imubridge run: error: " + dir.path().string() + ": is a directory, not a configuration file\n");

  r = run_imubridge("run --link imu=/dev/null:imubridge --db " + dir.path().string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(count_lines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find(dir.path().string() + ": is a directory, not a database file"), std::string::npos) << r.err;

  r = run_imubridge("run --link imu=/dev/null:imubridge --db " + (dir / "missing/x.db").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(count_lines(r.err), 1) << r.err;
  EXPECT_NE(
      r.err.find((dir / "missing/x.db").string() + ": its directory " + (dir / "missing").string() + " does not exist"),
      std::string::npos)
      << r.err;
}

TEST(RunCli, AFileThatIsNotADatabaseIsRefusedAtStart) {
  TempDir dir;
  std::ofstream(dir / "notes.db") << "shopping list\n";
  const auto r = run_imubridge("run --link imu=/dev/null:imubridge --db " + (dir / "notes.db").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("file is not a database"), std::string::npos) << r.err;
  EXPECT_EQ(slurp(dir / "notes.db"), "shopping list\n");
}

TEST(ListPortsCli, JsonIsAnArrayOfPortsWithPaths) {
  const auto r = run_imubridge("list-ports --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto ports = nlohmann::json::parse(r.out);
  ASSERT_TRUE(ports.is_array());
  for (const auto& port : ports) EXPECT_EQ(port.at("path").get<std::string>().rfind("/dev/", 0), 0u) << port;
}

}  // namespace
}  // namespace imubridge::test
