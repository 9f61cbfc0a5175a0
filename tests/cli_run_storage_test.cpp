// `imubridge run` at the limits of its disk: the free-space guard, the size cap's rotation, and a write that fails.
// In every case the daemon stays up for its links and outputs, and every file it leaves is an intact database.
#include <fstream>
#include <nlohmann/json.hpp>

#include "pipeline/estimation_stage.hpp"
#include "tests/cli_run_harness.hpp"

namespace imubridge::test {
namespace {

std::size_t total_size(const std::vector<std::vector<std::uint8_t>>& pieces) {
  std::size_t n = 0;
  for (const auto& p : pieces) n += p.size();
  return n;
}

class RunStorageTest : public ::testing::Test {
 protected:
  void start(const std::string& store_settings, const SpawnOptions& options = {}) {
    std::ofstream(dir_ / "imubridge.toml")
        << "[store]\npath = \"" << db_.string() << "\"\n"
        // The axes declared, so estimates follow from the first samples (an auto link waits to detect them).
        << store_settings << "\n[[link]]\nname = \"imu\"\ndevice = \"" << tty_.string() << "\"\naxes = \"frd\"\n";
    daemon_ = std::make_unique<Process>(std::vector<std::string>{"run", "--config", (dir_ / "imubridge.toml").string()},
                                        dir_ / "stderr", options);
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
  fs::path db_ = dir_ / "run.db", tty_ = dir_ / "tty";
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
  EXPECT_EQ(count_of(daemon_->log(), "not recording: only"), 1) << daemon_->log();
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
  // A frame cut by a rotation is decodable in neither file (its bytes are all kept, and counted as discarded).
  EXPECT_GE(seqs.size(), frames.size() - (files - 1));
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

}  // namespace
}  // namespace imubridge::test
