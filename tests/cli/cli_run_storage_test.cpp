// `imubridge run` at the limits of its disk: the free-space guard, the size cap's rotation, and a write that fails.
// In every case the daemon stays up for its links and outputs, and every file it leaves is an intact database.
#include <sys/socket.h>
#include <sys/un.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "pipeline/estimation_stage.hpp"
#include "tests/support/cli_run_harness.hpp"

namespace imubridge::test {
namespace {

std::size_t total_size(const std::vector<std::vector<std::uint8_t>>& pieces) {
  std::size_t n = 0;
  for (const auto& p : pieces) n += p.size();
  return n;
}

// A NOTIFY_SOCKET as systemd listens on: what the daemon tells it, in order.
class NotifyListener {
 public:
  explicit NotifyListener(const fs::path& path) : path_(path), fd_(::socket(AF_UNIX, SOCK_DGRAM | SOCK_NONBLOCK, 0)) {
    sockaddr_un address{.sun_family = AF_UNIX, .sun_path = {}};
    path.string().copy(address.sun_path, sizeof address.sun_path - 1);
    EXPECT_EQ(::bind(fd_, reinterpret_cast<sockaddr*>(&address), sizeof address), 0);
  }
  ~NotifyListener() { ::close(fd_); }
  const fs::path& path() const { return path_; }
  // Whether `what` arrives after what an earlier call found.
  bool hears(const std::string& what) {
    return eventually([&] {
      char buffer[4096];
      for (ssize_t n; (n = ::recv(fd_, buffer, sizeof buffer, 0)) > 0;) heard.append(buffer, n).append("\n");
      const auto at = heard.find(what, from_);
      if (at == std::string::npos) return false;
      from_ = at + what.size();
      return true;
    });
  }
  std::string heard;

 private:
  fs::path path_;
  int fd_;
  std::size_t from_ = 0;
};

class RunStorageTest : public ::testing::Test {
 protected:
  // A configuration recording into db_ from the link on `tty`.
  void write_config(const std::string& store_settings, const fs::path& config = {}, const fs::path& tty = {}) {
    std::ofstream(config.empty() ? config_ : config)
        << "[store]\npath = \"" << db_.string()
        << "\"\n"
        // The axes declared, so estimates follow from the first samples (an auto link waits to detect them).
        << store_settings << "\n[[link]]\nname = \"imu\"\ndevice = \"" << (tty.empty() ? tty_ : tty).string()
        << "\"\naxes = \"frd\"\n";
  }
  void start(const std::string& store_settings, const SpawnOptions& options = {}) {
    write_config(store_settings);
    daemon_ = std::make_unique<Process>(std::vector<std::string>{"run", "--config", config_.string()}, dir_ / "stderr",
                                        options);
    ASSERT_TRUE(daemon_->wait_for_log("link 'imu': reading")) << daemon_->log();
  }
  // The link's counters as the daemon logs them on SIGUSR1, once it has read `bytes` bytes; null if it does not.
  // Asks at most 100 times: the log is a file too, and must stay far below the write-failure test's size limit.
  nlohmann::json counters_after_reading(std::size_t bytes) {
    for (int asked = 1; asked <= 100; ++asked) {
      daemon_->signal(SIGUSR1);
      if (!eventually([&] { return count_of(daemon_->log(), "stats {") >= asked; })) break;
      const std::string log = daemon_->log();
      const auto at = log.rfind("stats {") + 6;
      const auto link = nlohmann::json::parse(log.substr(at, log.find('\n', at) - at))["links"]["imu"];
      if (link["bytes_read"] == bytes) return link;
      std::this_thread::sleep_for(100ms);
    }
    return nullptr;
  }
  void stop() {
    daemon_->signal(SIGTERM);
    ASSERT_EQ(daemon_->wait(), 0) << daemon_->log();
  }

  TempDir dir_;
  fs::path db_ = dir_ / "run.db", tty_ = dir_ / "tty", config_ = dir_ / "imubridge.toml";
  cli::PtyPair pty_{tty_};
  std::unique_ptr<Process> daemon_;
};

TEST_F(RunStorageTest, BelowTheFreeSpaceFloorNothingIsWrittenButTheLinksAreServed) {
  start("min_free_mib = 1e9");  // a petabyte: no disk here has that much free
  const auto frames = simulated_frames(100);
  write_paced(pty_, frames);
  const auto link = counters_after_reading(total_size(frames));
  ASSERT_FALSE(link.is_null()) << daemon_->log();
  EXPECT_EQ(link["samples"], frames.size());
  // Estimated for the outputs all the same: all but the first `delay` samples and the last `delay`, which wait for
  // the samples that complete their differentiator window.
  const int delay = pipeline::EstimationStage(estimator::ModelParams{}).delay_samples();
  EXPECT_EQ(link["estimates"], frames.size() - 2 * delay);
  stop();
  EXPECT_EQ(count_of(daemon_->log(), "error: not recording: only"), 1) << daemon_->log();
  EXPECT_FALSE(fs::exists(db_));
}

TEST_F(RunStorageTest, TheSizeCapRotatesIntoChainedFilesThatKeepEveryByte) {
  const auto frames = simulated_frames(8000);
  start("min_free_mib = 0\nmax_size_mib = 1\ncommit_interval_ms = 50");
  write_paced(pty_, frames);
  ASSERT_FALSE(counters_after_reading(total_size(frames)).is_null()) << daemon_->log();
  stop();
  ASSERT_GE(count_of(daemon_->log(), "reached store.max_size_mib"), 1) << daemon_->log();

  // Follow the chain from the configured file: each session names the file that continues it, and that file's
  // session names it back.
  std::vector<std::uint8_t> received;
  std::vector<std::uint64_t> seqs;
  int files = 0;
  std::string previous;
  for (fs::path file = db_; !file.empty(); ++files) {
    ASSERT_EQ(integrity_check(file), "ok") << file;
    const store::Store store(file, {.read_only = true});
    const auto sessions = store.sessions();
    ASSERT_EQ(sessions.size(), 1u) << file;
    const auto& session = sessions[0];
    EXPECT_TRUE(session.ended_wall_ns.has_value()) << file;
    store.for_each_chunk(session.id, std::nullopt, [&](const store::Chunk& c) {
      received.insert(received.end(), c.bytes.begin(), c.bytes.end());
    });
    store.for_each_sample(session.id, std::nullopt, [&](const protocol::Sample& s) { seqs.push_back(s.seq); });
    std::string continues, continued_in;
    for (const auto& e : store.events(session.id)) {
      if (e.kind == "note" && e.detail.rfind("continues ", 0) == 0) continues = e.detail.substr(10);
      if (e.kind == "note" && e.detail.rfind("continued in ", 0) == 0) continued_in = e.detail.substr(13);
    }
    EXPECT_EQ(continues, previous);
    previous = file.filename().string() + " session " + std::to_string(session.id);
    file = continued_in.empty() ? fs::path() : file.parent_path() / continued_in.substr(0, continued_in.find(' '));
  }
  EXPECT_GE(files, 2);
  std::vector<std::uint8_t> sent;
  for (const auto& f : frames) sent.insert(sent.end(), f.begin(), f.end());
  EXPECT_EQ(received, sent) << "the raw bytes, split over the files, are the whole stream";
  // One decoder heard the whole stream: a frame cut by a rotation is decoded, and stored in the file it ends in.
  EXPECT_EQ(seqs.size(), frames.size());
  EXPECT_TRUE(std::is_sorted(seqs.begin(), seqs.end()));
}

TEST_F(RunStorageTest, AFailedWriteStopsRecordingCleanlyAndTheDaemonGoesOn) {
  // Every file the daemon writes may grow to 256 KiB: the database's write-ahead log soon cannot.
  start("min_free_mib = 0", {.env = {}, .file_size_limit = 256 * 1024});
  const auto frames = simulated_frames(4000);
  write_paced(pty_, frames);
  const auto link = counters_after_reading(total_size(frames));
  ASSERT_FALSE(link.is_null()) << daemon_->log();
  stop();
  EXPECT_EQ(count_of(daemon_->log(), "recording stopped: "), 1) << daemon_->log();
  // Decoding goes on for the outputs. Stopping the recorder's decoder may cut the frame it was in the middle of:
  // then its bytes are counted as discarded, and nothing else is lost.
  const std::uint64_t samples = link["samples"], discarded = link["decoders"]["imubridge"]["bytes_discarded"];
  EXPECT_GE(samples, frames.size() - 1);
  EXPECT_EQ(samples * frames[0].size() + discarded, total_size(frames));
  EXPECT_EQ(integrity_check(db_), "ok");
  EXPECT_FALSE(committed_samples(db_).empty()) << "what was committed before the failure is kept";
}

// The samples of each session of the store, by session id.
std::map<std::int64_t, std::vector<protocol::Sample>> samples_by_session(const fs::path& db) {
  std::map<std::int64_t, std::vector<protocol::Sample>> samples;
  const store::Store store(db, {.read_only = true});
  for (const auto& session : store.sessions()) {
    store.for_each_sample(session.id, std::nullopt,
                          [&](const protocol::Sample& s) { samples[session.id].push_back(s); });
  }
  return samples;
}

std::vector<store::Session> sessions_of(const fs::path& db) { return store::Store(db, {.read_only = true}).sessions(); }

// min_free_mib, reloaded by SIGHUP, stands for a disk that fills up and is cleared: the periodic check of free space
// does the rest.
TEST_F(RunStorageTest, RecordingStoppedForWantOfFreeSpaceResumesInANewSessionOnceThereIsSpace) {
  NotifyListener systemd(dir_ / "notify");
  start("min_free_mib = 0", {.env = {{"NOTIFY_SOCKET", systemd.path().string()}}, .file_size_limit = {}});
  ASSERT_TRUE(systemd.hears("STATUS=recording session 1 into " + db_.string())) << systemd.heard;
  const auto frames = simulated_frames(600);
  const auto part = [&](std::size_t from, std::size_t to) {
    return std::vector<std::vector<std::uint8_t>>(frames.begin() + from, frames.begin() + to);
  };
  write_paced(pty_, part(0, 200));
  ASSERT_TRUE(wait_for_samples(db_, 190)) << daemon_->log();

  write_config("min_free_mib = 1e9");
  daemon_->signal(SIGHUP);
  ASSERT_TRUE(daemon_->wait_for_log("recording stopped: only")) << daemon_->log();
  ASSERT_TRUE(systemd.hears("STATUS=not recording: only ")) << systemd.heard;
  write_paced(pty_, part(200, 400));  // decoded and estimated, not recorded
  ASSERT_FALSE(counters_after_reading(total_size(part(0, 400))).is_null()) << daemon_->log();

  write_config("min_free_mib = 0");
  daemon_->signal(SIGHUP);
  ASSERT_TRUE(daemon_->wait_for_log("recording session 2 into " + db_.string())) << daemon_->log();
  ASSERT_TRUE(systemd.hears("STATUS=recording session 2 into " + db_.string())) << systemd.heard;
  write_paced(pty_, part(400, 600));
  ASSERT_TRUE(eventually([&] { return samples_by_session(db_)[2].size() >= 190; })) << daemon_->log();
  stop();

  const std::string log = daemon_->log();
  EXPECT_EQ(count_of(log, "recording stopped: "), 1) << log;
  EXPECT_EQ(count_of(log, "; resumes after run.db session 1, which stopped: only "), 1) << log;
  auto samples = samples_by_session(db_);
  ASSERT_EQ(samples.size(), 2u);
  EXPECT_GE(samples[2].front().seq, samples[1].back().seq + 200) << "nothing was recorded while space was short";
  const store::Store store(db_, {.read_only = true});
  for (const auto& session : store.sessions()) EXPECT_STREQ(store::state_name(session), "ended") << session.id;
  const auto events = store.events(2);
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events[0].kind, "note");
  EXPECT_EQ(events[0].detail.rfind("resumes after run.db session 1, which stopped: only ", 0), 0u) << events[0].detail;
}

TEST_F(RunStorageTest, ASessionLeftOpenByAKilledRecorderIsEndedAsInterruptedAtTheNextStart) {
  start("min_free_mib = 0");
  write_paced(pty_, simulated_frames(200));
  ASSERT_TRUE(wait_for_samples(db_, 190)) << daemon_->log();
  // A second daemon recording into the same file from another device: session 2, while the first still runs.
  const fs::path tty2 = dir_ / "tty2", config2 = dir_ / "second.toml";
  cli::PtyPair pty2(tty2);
  write_config("min_free_mib = 0", config2, tty2);
  Process second({"run", "--config", config2.string()}, dir_ / "stderr2");
  ASSERT_TRUE(second.wait_for_log("recording session 2")) << second.log();
  ASSERT_EQ(sessions_of(db_).size(), 2u);
  EXPECT_STREQ(store::state_name(sessions_of(db_)[0]), "open") << "its writer runs";

  daemon_->signal(SIGKILL);
  ASSERT_EQ(daemon_->wait(), -SIGKILL);
  std::int64_t last_wall_ns = 0;
  {
    const store::Store store(db_, {.read_only = true});
    store.for_each_chunk(1, std::nullopt, [&](const store::Chunk& c) { last_wall_ns = c.recv_wall_ns; });
    for (const auto& e : store.events(1)) last_wall_ns = std::max(last_wall_ns, e.wall_ns);
  }
  ASSERT_GT(last_wall_ns, 0);

  Process restarted({"run", "--config", config_.string()}, dir_ / "stderr3");
  ASSERT_TRUE(restarted.wait_for_log("recording session 3")) << restarted.log();
  EXPECT_EQ(count_of(restarted.log(), "session 1 in " + db_.string() + " was left open by process " +
                                          std::to_string(daemon_->pid()) + ", which has ended"),
            1)
      << restarted.log();
  auto sessions = sessions_of(db_);
  ASSERT_EQ(sessions.size(), 3u);
  EXPECT_STREQ(store::state_name(sessions[0]), "interrupted");
  EXPECT_EQ(sessions[0].ended_wall_ns, last_wall_ns);
  EXPECT_STREQ(store::state_name(sessions[1]), "open") << "the second daemon still runs";
  EXPECT_EQ(sessions[1].writer->pid, second.pid());

  restarted.signal(SIGTERM);
  ASSERT_EQ(restarted.wait(), 0) << restarted.log();
  second.signal(SIGTERM);
  ASSERT_EQ(second.wait(), 0) << second.log();
  sessions = sessions_of(db_);
  EXPECT_STREQ(store::state_name(sessions[0]), "interrupted");
  EXPECT_STREQ(store::state_name(sessions[1]), "ended");
  EXPECT_STREQ(store::state_name(sessions[2]), "ended");
  {
    const store::Store store(db_, {.read_only = true});
    const auto events = store.events(1);
    EXPECT_EQ(events.back().kind, "interrupted");
    EXPECT_EQ(events.back().wall_ns, last_wall_ns);
  }

  const auto list = run_imubridge("list --db " + db_.string() + " --json");
  ASSERT_EQ(list.exit_code, 0) << list.err;
  const auto listed = nlohmann::json::parse(list.out);
  ASSERT_EQ(listed.size(), 3u) << list.out;
  EXPECT_EQ(listed[0]["state"], "interrupted");
  EXPECT_EQ(listed[0]["ended_wall_ns"], last_wall_ns);
  EXPECT_EQ(listed[1]["state"], "ended");
  const auto table = run_imubridge("list --db " + db_.string());
  ASSERT_EQ(table.exit_code, 0) << table.err;
  EXPECT_EQ(count_of(table.out, " interrupted "), 1) << table.out;

  const auto exported = run_imubridge("export --db " + db_.string() + " --session 1 --what samples");
  ASSERT_EQ(exported.exit_code, 0) << exported.err;
  EXPECT_EQ(exported.err.rfind("session 1: interrupted (its writer, process " + std::to_string(daemon_->pid()), 0), 0u)
      << exported.err;
  EXPECT_GE(count_of(exported.out, "\n"), 191) << "a header and every sample";
  const auto replayed = run_imubridge("replay --db " + db_.string() + " --session 1");
  ASSERT_EQ(replayed.exit_code, 0) << replayed.err;
  EXPECT_NE(replayed.err.find("session 1: interrupted (its writer, process "), std::string::npos) << replayed.err;
  EXPECT_EQ(integrity_check(db_), "ok");
}

}  // namespace
}  // namespace imubridge::test
