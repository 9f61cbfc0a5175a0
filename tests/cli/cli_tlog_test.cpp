// `imubridge sim --protocol mavlink --tlog` and `imubridge import tlog` as a user runs them: a simulated flight written
// as a telemetry log and imported gives the samples and the trajectory the simulator recorded itself (`sim --db`);
// the same seed writes the same file; a truncated log imports up to the damage and says so; garbage is one line.
#include <gtest/gtest.h>
#include <pty.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "store/store.hpp"
#include "tests/support/run_command.hpp"
#include "tests/support/temp_dir.hpp"

namespace imubridge::test {
namespace {

constexpr const char* kFlight = "sim --scenario paper --seed 4 --duration 3 --protocol mavlink";

std::int64_t last_line_number(const std::string& out) {
  const std::size_t end = out.find_last_not_of('\n');
  const std::size_t start = out.find_last_of('\n', end);
  return std::stoll(out.substr(start == std::string::npos ? 0 : start + 1));
}

std::vector<protocol::Sample> samples(const store::Store& store, std::int64_t session) {
  std::vector<protocol::Sample> out;
  store.for_each_sample(session, std::nullopt, [&](const protocol::Sample& s) { out.push_back(s); });
  return out;
}

std::vector<store::ReferenceRow> reference(const store::Store& store, std::int64_t session) {
  std::vector<store::ReferenceRow> out;
  store.for_each_reference(session, [&](const store::ReferenceRow& r) { out.push_back(r); });
  return out;
}

TEST(TlogCli, ASimulatedFlightRoundTripsThroughATlog) {
  TempDir dir;
  const std::string tlog = (dir / "flight.tlog").string(), db = (dir / "flights.db").string();
  auto r = run_imubridge(std::string(kFlight) + " --tlog " + tlog);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string bytes = slurp(tlog);
  ASSERT_EQ(run_imubridge(std::string(kFlight) + " --tlog " + (dir / "again.tlog").string()).exit_code, 0);
  EXPECT_EQ(slurp(dir / "again.tlog"), bytes);  // the same seed, the same file: times are a fixed epoch + sim time

  r = run_imubridge("import tlog " + tlog + " --db " + db);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::int64_t imported = last_line_number(r.out);
  EXPECT_NE(r.err.find("imported 600 IMU samples (HIGHRES_IMU id 0 from system 1, component 1, 3.0 s)"),
            std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("reference: 60 rows (LOCAL_POSITION_NED + ATTITUDE from system 1, component 1)"),
            std::string::npos)
      << r.err;
  EXPECT_EQ(r.err.find("warning"), std::string::npos) << r.err;
  // stderr is a file here, no terminal: no progress line, not even an empty one.
  EXPECT_EQ(r.err.find('\r'), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("importing"), std::string::npos) << r.err;
  EXPECT_TRUE(r.err.starts_with("imported 600 IMU samples")) << r.err;

  // The simulator's own recording of the same flight: the samples it decoded and its truth at every sample.
  r = run_imubridge(std::string(kFlight) + " --db " + db);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::int64_t simulated = last_line_number(r.out);

  const store::Store store(db);
  const auto got = samples(store, imported), want = samples(store, simulated);
  ASSERT_EQ(got.size(), 600u);
  ASSERT_EQ(got.size(), want.size());
  const std::int64_t epoch_ns = got.front().recv_mono_ns;  // the tlog's times are a fixed epoch + the flight's time
  EXPECT_EQ(epoch_ns, 1'704'067'200'000'000'000);
  for (std::size_t i = 0; i < got.size(); ++i) {
    ASSERT_EQ(got[i].device_time_us, want[i].device_time_us) << i;
    ASSERT_EQ(got[i].recv_mono_ns - epoch_ns, want[i].recv_mono_ns) << i;
    for (int a = 0; a < 3; ++a) {  // both decoded from the same HIGHRES_IMU floats
      ASSERT_EQ(got[i].accel[a], want[i].accel[a]) << i;
      ASSERT_EQ(got[i].gyro[a], want[i].gyro[a]) << i;
    }
  }
  const auto ref = reference(store, imported), truth = reference(store, simulated);
  ASSERT_EQ(ref.size(), 60u);
  ASSERT_EQ(truth.size(), 600u);
  for (std::size_t k = 0; k < ref.size(); ++k) {
    const store::ReferenceRow& t = truth[10 * k];  // LOCAL_POSITION_NED and ATTITUDE go with every tenth sample
    ASSERT_EQ(ref[k].t_ns - epoch_ns, t.t_ns) << k;
    for (int a = 0; a < 3; ++a) {  // floats on the wire
      EXPECT_NEAR(ref[k].position[a], t.position[a], 1e-6 * (1 + std::abs(t.position[a]))) << k;
      EXPECT_NEAR((*ref[k].velocity)[a], (*t.velocity)[a], 1e-6 * (1 + std::abs((*t.velocity)[a]))) << k;
    }
    double dot = 0;  // the angle between the two attitudes is 2 acos |q . qt|
    for (int a = 0; a < 4; ++a) dot += ref[k].quat_wxyz[a] * t.quat_wxyz[a];
    EXPECT_LT(2 * std::acos(std::min(1.0, std::abs(dot))), 1e-6) << k;
  }

  // Replayed, the import's session gives the same samples again.
  r = run_imubridge("replay --db " + db + " --session " + std::to_string(imported));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("600 samples"), std::string::npos) << r.err;
}

TEST(TlogCli, ATruncatedLogImportsUpToTheDamageAndSaysSo) {
  TempDir dir;
  const std::string tlog = (dir / "flight.tlog").string(), db = (dir / "flights.db").string();
  ASSERT_EQ(run_imubridge(std::string(kFlight) + " --tlog " + tlog).exit_code, 0);
  const std::uintmax_t size = std::filesystem::file_size(tlog);
  std::filesystem::resize_file(tlog, size - 30);  // into the last record, a HIGHRES_IMU of 82 bytes
  const auto r = run_imubridge("import tlog " + tlog + " --db " + db);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("imported 599 IMU samples"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("\nwarning: 52 bytes of " + tlog +
                       " damaged: the last record, cut short (52 bytes of its 82; the file ends); the records around "
                       "them are imported (at byte " +
                       std::to_string(size - 82) + ", after record 719)\n"),
            std::string::npos)
      << r.err;
}

// On a terminal the import draws its progress line, ended before the summary.
TEST(TlogCli, ImportShowsItsProgressOnATerminal) {
  TempDir dir;
  const std::string tlog = (dir / "flight.tlog").string(), db = (dir / "flights.db").string();
  ASSERT_EQ(run_imubridge(std::string(kFlight) + " --tlog " + tlog).exit_code, 0);
  int master = -1, slave = -1;
  ASSERT_EQ(::openpty(&master, &slave, nullptr, nullptr, nullptr), 0);
  const std::string out = (dir / "out.txt").string();
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::close(master);
    ::dup2(slave, STDERR_FILENO);
    ::close(slave);
    ::execl("/bin/sh", "sh", "-c",
            (std::string(IMUBRIDGE_BIN) + " import tlog " + tlog + " --db " + db + " >" + out + " </dev/null").c_str(),
            static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ::close(slave);
  std::string err;
  char buffer[4096];
  for (ssize_t n; (n = ::read(master, buffer, sizeof buffer)) > 0;) err.append(buffer, static_cast<std::size_t>(n));
  ::close(master);  // read() ends with EIO once the program, the slave's last holder, has exited
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << err;
  const std::size_t line = err.find("importing flight.tlog 100% ");
  ASSERT_NE(line, std::string::npos) << err;
  const std::size_t summary = err.find("imported 600 IMU samples");
  ASSERT_NE(summary, std::string::npos) << err;
  EXPECT_LT(line, summary);
  EXPECT_NE(err.substr(line, summary - line).find('\n'), std::string::npos) << err;  // the summary on a line of its own
  EXPECT_GT(last_line_number(slurp(out)), 0);
}

TEST(TlogCli, GarbageIsRefusedInOneLine) {
  TempDir dir;
  const std::string path = (dir / "notes.tlog").string();
  std::ofstream(path) << "these are my flight notes, not a telemetry log\n";
  const auto r = run_imubridge("import tlog " + path + " --db " + (dir / "flights.db").string());
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(count_lines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find(path + ": not a MAVLink telemetry log (tlog)"), std::string::npos) << r.err;
  const auto wrong = run_imubridge("sim --duration 1 --tlog " + (dir / "x.tlog").string());  // imubridge frames
  EXPECT_EQ(wrong.exit_code, 2);
  EXPECT_EQ(count_lines(wrong.err), 1) << wrong.err;
  EXPECT_NE(wrong.err.find("--protocol mavlink"), std::string::npos) << wrong.err;
}

// `import dataflash` reads ArduPilot logs (tests/importers/dataflash_import_test.cpp); what is none is refused in one
// line.
TEST(TlogCli, WhatIsNoDataflashLogIsRefusedInOneLine) {
  TempDir dir;
  const std::string path = (dir / "00000001.BIN").string();
  std::ofstream(path) << "these are my flight notes, not a DataFlash log\n";
  const std::string db = (dir / "flights.db").string();
  const auto r = run_imubridge("import dataflash " + path + " --db " + db);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(count_lines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find(path + ": not an ArduPilot DataFlash log"), std::string::npos) << r.err;
  if (std::filesystem::exists(db)) {
    EXPECT_TRUE(store::Store(db).sessions().empty()) << "no session is written";
  }
}

}  // namespace
}  // namespace imubridge::test
