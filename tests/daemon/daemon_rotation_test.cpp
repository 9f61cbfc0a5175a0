// A rotation changes the file the daemon records into, not the flight it estimates: its decoder and its live filter run
// on through the rotation, so the files, read one after the other, hold every sample of the link and the estimates of
// a run that never rotated, bit for bit.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "daemon/config_file.hpp"
#include "daemon/daemon.hpp"
#include "estimator/params.hpp"
#include "pipeline/estimation_stage.hpp"
#include "tests/support/cli_run_harness.hpp"
#include "tests/support/paper_params.hpp"

namespace imubridge::daemon {
namespace {

namespace fs = std::filesystem;

// What one file of the chain holds of its session.
struct RecordedFile {
  std::vector<protocol::Sample> samples;
  std::vector<store::Estimate> estimates;  // of its live run
  std::string params_json;                 // the live run's
};

// The files from `first` on, in order: each session's last note names the file that continues it.
std::vector<RecordedFile> follow_chain(const fs::path& first) {
  std::vector<RecordedFile> files;
  for (fs::path file = first; !file.empty();) {
    const store::Store store(file, {.read_only = true});
    const auto sessions = store.sessions();
    if (sessions.size() != 1u) {
      ADD_FAILURE() << file << " holds " << sessions.size() << " sessions";
      break;
    }
    RecordedFile& f = files.emplace_back();
    store.for_each_sample(sessions[0].id, std::nullopt, [&](const protocol::Sample& s) { f.samples.push_back(s); });
    for (const auto& run : store.runs(sessions[0].id)) {
      if (run.info.kind != "live") continue;
      f.params_json = run.info.params_json;
      store.for_each_estimate(run.id, [&](const store::Estimate& e) { f.estimates.push_back(e); });
    }
    std::string continued_in;
    for (const auto& e : store.events(sessions[0].id)) {
      if (e.kind == "note" && e.detail.rfind("continued in ", 0) == 0) continued_in = e.detail.substr(13);
    }
    file = continued_in.empty() ? fs::path() : file.parent_path() / continued_in.substr(0, continued_in.find(' '));
  }
  return files;
}

std::size_t committed_samples_in(const fs::path& dir) {
  std::size_t n = 0;
  for (const auto& entry : fs::directory_iterator(dir)) {
    if (entry.path().extension() == ".db") n += test::committed_samples(entry.path()).size();
  }
  return n;
}

bool connected(const fs::path& db) {
  try {
    const store::Store store(db, {.read_only = true});
    for (const auto& session : store.sessions()) {
      for (const auto& e : store.events(session.id)) {
        if (e.kind == "connected") return true;
      }
    }
  } catch (const store::StoreError&) {  // not created yet
  }
  return false;
}

TEST(DaemonRotation, TheLiveFilterRunsOnThroughARotation) {
  test::TempDir dir;
  const fs::path db = dir / "run.db", tty = dir / "tty", params = dir / "params.json";
  cli::PtyPair pty(tty);
  std::ofstream(params) << nlohmann::json(test::paper_params()).dump();
  Daemon daemon(parse_config("params = \"" + params.string() + "\"\n[store]\npath = \"" + db.string() +
                                 "\"\nmin_free_mib = 0\nmax_size_mib = 1\ncommit_interval_ms = 50\n"
                                 "[[link]]\nname = \"imu\"\ndevice = \"" +
                                 tty.string() + "\"\naxes = \"frd\"\n",
                             "test.toml"));
  std::thread serving([&] { daemon.run(); });
  ASSERT_TRUE(test::eventually([&] { return connected(db); })) << "the daemon never opened its link";
  const auto frames = test::simulated_frames(8000);
  test::write_paced(pty, frames);
  pty.drain();
  const bool all_stored = test::eventually([&] { return committed_samples_in(dir.path()) >= frames.size(); });
  daemon.stop();
  serving.join();
  EXPECT_TRUE(all_stored) << committed_samples_in(dir.path()) << " of " << frames.size() << " samples stored";

  const std::vector<RecordedFile> files = follow_chain(db);
  ASSERT_GE(files.size(), 2u) << "the size cap rotated the recording";
  // Every sample of the link, none lost to a frame cut by a rotation: one decoder heard the whole stream.
  std::vector<protocol::Sample> samples;
  std::vector<store::Estimate> live;
  for (const RecordedFile& f : files) {
    samples.insert(samples.end(), f.samples.begin(), f.samples.end());
    live.insert(live.end(), f.estimates.begin(), f.estimates.end());
  }
  EXPECT_EQ(samples.size(), frames.size());
  std::size_t gaps = 0;
  for (std::size_t i = 1; i < samples.size(); ++i) gaps += samples[i].seq != samples[i - 1].seq + 1;
  EXPECT_EQ(gaps, 0u);

  // The run that never rotated: the same samples through one stage with the live run's parameters.
  pipeline::EstimationStage unrotated(estimator::parse_params(files[0].params_json, "the live run"));
  std::vector<store::Estimate> expected;
  for (protocol::Sample s : samples) {
    s.link_id = 0;  // one stream, whichever file it is stored in
    unrotated.update(s, expected);
  }
  for (auto& e : expected) e.link_id = 0;
  for (auto& e : live) e.link_id = 0;
  ASSERT_GT(expected.size(), 7000u);
  EXPECT_EQ(live.size(), expected.size());
  for (std::size_t i = 0; i < std::min(live.size(), expected.size()); ++i) {
    ASSERT_EQ(live[i], expected[i]) << "estimate " << i << " of " << live.size() << " (seq " << live[i].seq << ")";
  }

  // Right after the first rotation: the second file's first estimate is the next one of the unrotated run.
  ASSERT_FALSE(files[1].estimates.empty());
  const std::size_t first_after = files[0].estimates.size();
  store::Estimate after = files[1].estimates.front();
  after.link_id = 0;
  EXPECT_EQ(after, expected[first_after]);
  EXPECT_EQ(after.seq, files[0].estimates.back().seq + 1) << "no estimate is missing at the rotation";
}

}  // namespace
}  // namespace imubridge::daemon
