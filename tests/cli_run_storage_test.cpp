// `imubridge run` at the limits of its disk: the free-space guard, the size cap's rotation, and a write that fails.
// In every case the daemon stays up for its links and outputs, and every file it leaves is an intact database.
#include <fstream>
#include <nlohmann/json.hpp>

#include "tests/cli_run_harness.hpp"

namespace imubridge::test {
namespace {

class RunStorageTest : public ::testing::Test {
 protected:
  void start(const std::string& store_settings, const SpawnOptions& options = {}) {
    std::ofstream(dir_ / "imubridge.toml")
        << "[store]\npath = \"" << db_.string() << "\"\n"
        << store_settings << "\n[[link]]\nname = \"imu\"\ndevice = \"" << tty_.string() << "\"\n";
    daemon_ = std::make_unique<Process>(std::vector<std::string>{"run", "--config", (dir_ / "imubridge.toml").string()},
                                        dir_ / "stderr", options);
    ASSERT_TRUE(daemon_->wait_for_log("link 'imu': reading")) << daemon_->log();
  }
  // Whether the daemon gets to `count` samples processed, by the counters it logs on SIGUSR1. Asks at most 100
  // times: the log is a file too, and must stay far below the write-failure test's file size limit.
  bool processes(std::uint64_t count) {
    for (int asked = 1; asked <= 100; ++asked) {
      daemon_->signal(SIGUSR1);
      if (!eventually([&] { return count_of(daemon_->log(), "stats {") >= asked; })) return false;
      const std::string log = daemon_->log();
      const auto at = log.rfind("stats {") + 6;
      const auto stats = nlohmann::json::parse(log.substr(at, log.find('\n', at) - at));
      if (stats["links"]["imu"]["samples"].get<std::uint64_t>() >= count) return true;
      std::this_thread::sleep_for(100ms);
    }
    return false;
  }
  void stop() {
    daemon_->signal(SIGTERM);
    ASSERT_EQ(daemon_->wait(), 0) << daemon_->log();
  }

  TempDir dir_;
  fs::path db_ = dir_ / "run.db", tty_ = dir_ / "tty";
  cli::PtyPair pty_{tty_};
  std::unique_ptr<Process> daemon_;
};

TEST_F(RunStorageTest, BelowTheFreeSpaceFloorNothingIsWrittenButTheLinksAreServed) {
  start("min_free_mib = 1e9");  // a petabyte: no disk here has that much free
  write_paced(pty_, simulated_frames(100));
  EXPECT_TRUE(processes(100)) << daemon_->log();
  stop();
  EXPECT_EQ(count_of(daemon_->log(), "not recording: only"), 1) << daemon_->log();
  EXPECT_FALSE(fs::exists(db_));
}

TEST_F(RunStorageTest, TheSizeCapRotatesIntoChainedFilesThatKeepEveryByte) {
  const auto frames = simulated_frames(8000);
  start("min_free_mib = 0\nmax_size_mib = 1\ncommit_interval_ms = 50");
  write_paced(pty_, frames);
  ASSERT_TRUE(processes(frames.size() - 10)) << daemon_->log();  // a few frames may be cut by rotations
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
  // A frame cut by a rotation is decodable in neither file (its bytes are all kept, and counted as discarded).
  EXPECT_GE(seqs.size(), frames.size() - (files - 1));
  EXPECT_TRUE(std::is_sorted(seqs.begin(), seqs.end()));
}

TEST_F(RunStorageTest, AFailedWriteStopsRecordingCleanlyAndTheDaemonGoesOn) {
  // Every file the daemon writes may grow to 256 KiB: the database's write-ahead log soon cannot.
  start("min_free_mib = 0", {.env = {}, .file_size_limit = 256 * 1024});
  const auto frames = simulated_frames(4000);
  write_paced(pty_, frames);
  ASSERT_TRUE(processes(frames.size())) << daemon_->log();
  stop();
  EXPECT_EQ(count_of(daemon_->log(), "recording stopped: "), 1) << daemon_->log();
  EXPECT_EQ(integrity_check(db_), "ok");
  EXPECT_FALSE(committed_samples(db_).empty()) << "what was committed before the failure is kept";
}

}  // namespace
}  // namespace imubridge::test
