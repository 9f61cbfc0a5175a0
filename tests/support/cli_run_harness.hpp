#pragma once
// What the `imubridge run` tests share: the daemon as a child process (its stderr captured, signals sent), a
// pseudo-terminal fed with simulated imubridge frames, and bounded waits on what the daemon has committed. Waits
// poll for progress and give up after a generous bound: they never measure time.
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "cli/pty.hpp"
#include "protocol/wire_format.hpp"
#include "sim/frame_encoder.hpp"
#include "sim/scenario.hpp"
#include "store/store.hpp"
#include "tests/support/run_command.hpp"
#include "tests/support/temp_dir.hpp"

namespace imubridge::test {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

// Polls `done` until it holds, for at most `limit`; returns whether it did.
inline bool eventually(const std::function<bool()>& done, std::chrono::milliseconds limit = 20s) {
  for (const auto deadline = std::chrono::steady_clock::now() + limit; !done();) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(10ms);
  }
  return true;
}

struct SpawnOptions {
  std::map<std::string, std::string> env;  // set in the child, on top of ours
  std::optional<rlim_t> file_size_limit;   // RLIMIT_FSIZE: writes beyond it fail as on a full disk
};

// `imubridge <args>` as a child process; killed (SIGKILL) if still running when destroyed.
class Process {
 public:
  Process(const std::vector<std::string>& args, const fs::path& stderr_path, const SpawnOptions& options = {})
      : stderr_path_(stderr_path) {
    pid_ = ::fork();
    if (pid_ != 0) return;
    std::FILE* err = std::freopen(stderr_path.c_str(), "w", stderr);
    std::FILE* out = std::freopen("/dev/null", "w", stdout);
    if (!err || !out) ::_exit(127);
    ::close_range(3, ~0u,
                  0);  // a pty master inherited here would keep the "device" plugged in after the test unplugs it
    for (const auto& [name, value] : options.env) ::setenv(name.c_str(), value.c_str(), 1);
    if (options.file_size_limit) {
      const rlimit limit{*options.file_size_limit, *options.file_size_limit};
      ::setrlimit(RLIMIT_FSIZE, &limit);
      ::signal(SIGXFSZ, SIG_IGN);  // so a write past the limit fails with EFBIG instead of killing the process
    }
    std::vector<char*> argv{const_cast<char*>(IMUBRIDGE_BIN)};
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    ::execv(IMUBRIDGE_BIN, argv.data());
    ::_exit(127);
  }
  ~Process() {
    if (running()) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
  }
  Process(const Process&) = delete;
  Process& operator=(const Process&) = delete;

  pid_t pid() const { return pid_; }
  bool running() const { return pid_ > 0 && !status_; }
  void signal(int sig) const { ::kill(pid_, sig); }
  std::string log() const { return slurp(stderr_path_); }
  // The exit code, or -signal number; -1000 when it did not end within the bound (it is then killed).
  int wait(std::chrono::milliseconds limit = 20s) {
    const bool ended = eventually(
        [&] {
          int status = 0;
          if (::waitpid(pid_, &status, WNOHANG) == pid_) status_ = status;
          return status_.has_value();
        },
        limit);
    if (!ended) return -1000;
    return WIFEXITED(*status_) ? WEXITSTATUS(*status_) : -WTERMSIG(*status_);
  }
  bool wait_for_log(const std::string& text, std::chrono::milliseconds limit = 20s) const {
    return eventually([&] { return log().find(text) != std::string::npos; }, limit);
  }

 private:
  fs::path stderr_path_;
  pid_t pid_ = -1;
  std::optional<int> status_;
};

inline int count_of(const std::string& text, const std::string& needle) {
  int n = 0;
  for (auto at = text.find(needle); at != std::string::npos; at = text.find(needle, at + 1)) ++n;
  return n;
}

// A simulated flight's imubridge frames, one per IMU sample (paper scenario, 200 Hz).
inline std::vector<std::vector<std::uint8_t>> simulated_frames(std::size_t count, std::uint64_t seed = 3) {
  const auto samples = sim::simulate(sim::make_scenario("paper", seed, static_cast<double>(count) / 200.0 + 0.1));
  sim::FrameEncoder encoder(protocol::WireFormat::imubridge);
  std::vector<std::vector<std::uint8_t>> frames;
  for (std::size_t i = 0; i < count && i < samples.size(); ++i) encoder.encode(samples[i], frames.emplace_back());
  return frames;
}

// Writes in bursts with short pauses, as a radio would. Unlike PtyPair::write, which drops what does not fit as a
// UART would, this waits for the daemon to make room: a test's bytes are never lost before they reach it.
inline void write_paced(cli::PtyPair& pty, const std::vector<std::vector<std::uint8_t>>& pieces) {
  for (std::size_t i = 0; i < pieces.size(); ++i) {
    for (std::span<const std::uint8_t> rest(pieces[i]); !rest.empty();) {
      const ssize_t n = ::write(pty.master_fd(), rest.data(), rest.size());
      if (n > 0) {
        rest = rest.subspan(static_cast<std::size_t>(n));
      } else {
        ASSERT_TRUE(errno == EAGAIN || errno == EINTR) << std::strerror(errno);
        pollfd writable{pty.master_fd(), POLLOUT, 0};
        ASSERT_EQ(::poll(&writable, 1, 20'000), 1) << "the daemon stopped reading";
      }
    }
    if (i % 20 == 19) std::this_thread::sleep_for(1ms);
  }
}

// Read-only views of a database the daemon may still be writing.
inline std::vector<protocol::Sample> committed_samples(const fs::path& db) {
  std::vector<protocol::Sample> samples;
  try {
    const store::Store store(db, {.read_only = true});
    for (const auto& session : store.sessions()) {
      store.for_each_sample(session.id, std::nullopt, [&](const protocol::Sample& s) { samples.push_back(s); });
    }
  } catch (const store::StoreError&) {  // not created yet
  }
  return samples;
}

inline bool wait_for_samples(const fs::path& db, std::size_t count) {
  return eventually([&] { return committed_samples(db).size() >= count; });
}

// Sum of the counts of each event kind in a session.
inline std::map<std::string, std::int64_t> event_totals(const store::Store& store, std::int64_t session) {
  std::map<std::string, std::int64_t> totals;
  for (const auto& e : store.events(session)) totals[e.kind] += e.count;
  return totals;
}

inline std::string integrity_check(const fs::path& db) {
  store::Database database(db, /*read_only=*/true);
  store::Statement check(database, "PRAGMA integrity_check");
  return check.step() ? check.column_text(0) : "no answer";
}

}  // namespace imubridge::test
