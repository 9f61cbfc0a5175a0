#pragma once
// `imubridge run`: the ground-station daemon. One io_context thread serves every link: each chunk a port returns goes
// through the session engine (pipeline/session_engine.hpp), as replay's chunks do: decoded and estimated, then handed
// to the sinks: the recording (raw bytes, samples, losses and the live run's estimates: pipeline::SessionRecording,
// while there is one), the link's bridge and feedback, and the outputs (daemon/live_sinks.hpp). Operations (signals,
// systemd, storage limits, logs): docs/operations.md.
#include <chrono>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "daemon/asio.hpp"
#include "daemon/config.hpp"
#include "daemon/systemd_notify.hpp"
#include "estimator/imu_axes.hpp"
#include "estimator/params.hpp"
#include "protocol/sample.hpp"
#include "store/records.hpp"

namespace imubridge::pipeline {
class EstimationStage;
class SessionEngine;
class SessionSink;
}  // namespace imubridge::pipeline

namespace imubridge::daemon {

class Outputs;

// spdlog's default logger for the daemon: config.log_file if set, else stderr; on the journal, lines carry a syslog
// priority instead of a timestamp (journald keeps its own). Called again on SIGHUP, which reopens the file.
void configure_logging(const Config& config);

class Daemon {
 public:
  // Loads the parameters (std::invalid_argument), opens the outputs (std::runtime_error when a socket cannot be
  // opened) and the store (store::StoreError). `config_file`, when there is one, is read again on SIGHUP.
  explicit Daemon(Config config, std::optional<std::filesystem::path> config_file = {});
  ~Daemon();
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

  // Starts the links and serves them until SIGINT or SIGTERM (or stop()), then ends the session. Returns 0.
  int run();
  // From any thread: what SIGTERM does.
  void stop();

  // Everything counted so far, per link, for the store and the outputs: what the stats log line and SIGUSR1 show.
  nlohmann::json counters() const;

 private:
  struct Link;
  struct Recording;
  class RecordingSink;

  // Why the daemon is not recording, and where it records again once it can.
  struct NotRecording {
    std::filesystem::path path;  // the file recording resumes into
    std::string previous;        // the session that stopped, "run.db session 3"; empty if none began
    std::string reason;
    bool resumes = true;  // false once a file reached store.max_size_mib with on_full = "stop"
  };

  // Begins a session in `path`, its first event a note `note` (if any) saying what it continues. Throws StoreError,
  // leaving the daemon as it was.
  void open_recording(const std::filesystem::path& path, const std::string& note);
  void close_recording();
  // Ends the recording, if any; the links and outputs go on without one.
  void stop_recording(NotRecording why);
  NotRecording stopping_here(const std::string& reason, bool resumes = true) const;
  void rotate();
  void check_storage();
  // Every kStorageRetryInterval while not recording: records again once it can.
  void resume_tick();
  std::optional<std::uint64_t> free_bytes() const;
  std::optional<std::string> storage_problem() const;
  // Runs a store write; a failure ends the recording, never the daemon.
  template <typename Write>
  void record(Write&& write);

  // Construction's steps: what is done once a source's axes are resolved, for the engine's stage; a link's decoder,
  // port, bridge and feedback; the engine's sinks, the daemon's own first.
  void on_axes_resolved(const protocol::SourceKey& source, const estimator::AxesResolution& resolution);
  void add_link(const LinkConfig& link_config);
  void add_sinks();

  void on_open(Link& link, const std::string& path, bool reopened);
  void request_streams(Link& link);
  void on_lost(Link& link, const std::string& reason);
  void on_data(Link& link, std::span<const std::uint8_t> bytes);
  void write_to_link(Link& link, std::span<const std::uint8_t> bytes);

  void wait_for_signal();
  void reload();
  // Calls `tick` every `period` until the timer is cancelled.
  void every(boost::asio::steady_timer& timer, std::chrono::nanoseconds period, void (Daemon::*tick)());
  void commit_tick();
  void stats_tick();
  void log_stats() const;
  void watchdog_tick();
  void shutdown();
  void finish_links();
  std::string status_line() const;

  Config config_;
  std::optional<std::filesystem::path> config_file_;
  std::string params_note_;  // what PARAMS.json held that this flight does not fly with (filled by params_'s init)
  estimator::ModelParams params_;
  boost::asio::io_context io_;
  boost::asio::signal_set signals_;
  boost::asio::steady_timer commit_timer_, stats_timer_, watchdog_timer_, resume_timer_;
  SystemdNotifier systemd_;
  std::unique_ptr<Outputs> outputs_;
  std::unique_ptr<Recording> recording_;       // none while not recording (free space short, disk full, write error)
  std::optional<NotRecording> not_recording_;  // while recording_ is null
  int failures_in_a_row_ = 0;                  // stops and failed resumes: they space the next resume
  std::chrono::steady_clock::time_point next_resume_{};
  std::unique_ptr<pipeline::SessionEngine> engine_;
  std::vector<std::unique_ptr<pipeline::SessionSink>> sinks_;  // the engine's, in its order (RecordingSink first)
  std::vector<std::unique_ptr<Link>> links_;
  std::uint64_t commits_ = 0, rotations_ = 0;
  bool stopping_ = false;
};

}  // namespace imubridge::daemon
