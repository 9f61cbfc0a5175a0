#include "daemon/daemon.hpp"

#include <spdlog/pattern_formatter.h>
#include <spdlog/sinks/basic_file_sink.h>
#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>
#include <sys/statvfs.h>

#include <algorithm>
#include <csignal>
#include <ctime>
#include <fstream>
#include <nlohmann/json.hpp>
#include <map>
#include <sstream>
#include <stdexcept>

#include "daemon/asio.hpp"
#include "daemon/bridge.hpp"
#include "daemon/config_file.hpp"
#include "daemon/outputs.hpp"
#include "daemon/port_list.hpp"
#include "daemon/serial_link.hpp"
#include "daemon/vehicle_feedback.hpp"
#include "daemon/live_sinks.hpp"
#include "pipeline/estimation_stage.hpp"
#include "pipeline/session_engine.hpp"
#include "pipeline/radio_link.hpp"
#include "pipeline/recorded_session.hpp"
#include "store/store.hpp"

namespace imubridge::daemon {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
constexpr double kMiB = 1024.0 * 1024.0;
// While not recording, free space is looked at this often; recording resumes once there is min_free_mib plus
// kResumeMargin (a tenth of min_free_mib, at least kMinResumeMargin) free, so usage hovering at the floor does not
// start and stop a session at every check.
constexpr auto kStorageRetryInterval = std::chrono::seconds(5);
constexpr std::uint64_t kMinResumeMargin = 16ull << 20;
std::uint64_t resume_margin(std::uint64_t min_free_bytes) { return std::max(kMinResumeMargin, min_free_bytes / 10); }
// A store that keeps failing where free space looks fine (a quota, a file size limit) is tried less and less often:
// the first stop is retried at the next look, the n-th stop or failed resume in a row (n >= 2) waits
// kStorageRetryInterval * 2^(n-2) more, at most kMaxResumeDelay. A recording that lasted kSteadyRecording ends the row.
constexpr auto kMaxResumeDelay = std::chrono::minutes(5);
constexpr auto kSteadyRecording = std::chrono::minutes(1);
Clock::duration resume_delay(int failures_in_a_row) {
  if (failures_in_a_row <= 1) return Clock::duration::zero();
  const Clock::duration delay = kStorageRetryInterval * (1 << std::min(failures_in_a_row - 2, 6));
  return std::min<Clock::duration>(delay, kMaxResumeDelay);
}

std::int64_t mono_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
}
std::int64_t wall_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// journald reads a leading "<N>" as the line's syslog priority.
class SyslogPriority : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& msg, const std::tm&, spdlog::memory_buf_t& dest) override {
    static constexpr std::string_view kPriority[] = {"<7>", "<7>", "<6>", "<4>", "<3>", "<2>", ""};
    const std::string_view p = kPriority[msg.level];
    dest.append(p.data(), p.data() + p.size());
  }
  std::unique_ptr<custom_flag_formatter> clone() const override { return std::make_unique<SyslogPriority>(); }
};

// imubridge.db -> imubridge-20240521-143000.db beside it (UTC), with -2, -3, ... should that name be taken.
fs::path rotated_path(const fs::path& base) {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", &utc);
  const std::string stem = base.stem().string() + "-" + stamp;
  fs::path path = base.parent_path() / (stem + base.extension().string());
  for (int n = 2; fs::exists(path); ++n) {
    path = base.parent_path() / (stem + "-" + std::to_string(n) + base.extension().string());
  }
  return path;
}

// The database and its write-ahead log: SQLite moves pages from one to the other at checkpoints.
std::uint64_t database_size(const fs::path& path) {
  std::error_code ec;
  std::uint64_t size = 0;
  for (const fs::path& file : {path, fs::path(path.string() + "-wal")}) {
    const auto n = fs::file_size(file, ec);
    if (!ec) size += n;
  }
  return size;
}

std::string mib(std::uint64_t bytes) { return fmt::format("{:.1f} MiB", static_cast<double>(bytes) / kMiB); }

}  // namespace

void configure_logging(const Config& config) {
  spdlog::sink_ptr sink;
  if (config.log_file) {
    sink = std::make_shared<spdlog::sinks::basic_file_sink_mt>(config.log_file->string());
  } else {
    sink = std::make_shared<spdlog::sinks::stderr_sink_mt>();
  }
  auto formatter = std::make_unique<spdlog::pattern_formatter>();
  if (!config.log_file && stderr_is_journal()) {
    formatter->add_flag<SyslogPriority>('*').set_pattern("%*%v");
  } else {
    formatter->set_pattern("%Y-%m-%d %H:%M:%S.%e %l: %v");
  }
  sink->set_formatter(std::move(formatter));
  auto logger = std::make_shared<spdlog::logger>("imubridge", sink);
  logger->set_level(spdlog::level::from_str(config.log_level));
  logger->flush_on(spdlog::level::trace);  // lines are rare; each must reach the file before a crash could lose it
  spdlog::set_default_logger(std::move(logger));
}

struct Daemon::Recording {
  Recording(const fs::path& file, const StoreConfig& config)
      : path(file), store(file, store::StoreOptions{.commit_interval = config.commit_interval,
                                               .background_checkpoint = std::chrono::seconds(1)}) {}
  fs::path path;
  store::Store store;
  std::int64_t session = 0, run = 0;
  Clock::time_point since = Clock::now();

  // As notes name it in the session that continues it: "imubridge.db session 4".
  std::string name() const { return fmt::format("{} session {}", path.filename().string(), session); }
};

struct Daemon::Link {
  std::size_t index = 0;  // in links_, and the engine's link number
  LinkConfig config;
  std::unique_ptr<SerialLink> port;
  std::unique_ptr<LinkBridge> bridge;
  std::optional<VehicleFeedback> feedback;
  std::int64_t store_link = 0;  // in the current recording; also the link id of its samples while not recording
  std::unique_ptr<pipeline::LinkRecorder> recorder;          // while recording
  std::unique_ptr<pipeline::LinkDecoder> decoder;            // while not: the samples still reach estimates and outputs
  std::map<std::string, protocol::DecoderCounters> retired;  // counts of decoders a rotation or a stop replaced
  std::uint64_t samples = 0, estimates = 0, tx_chunks = 0;
  std::optional<std::int64_t> lost_at_ns;
  std::map<std::uint32_t, std::uint32_t> clock_epochs;  // by sample stream (an XBee link has one per radio)
  std::unique_ptr<pipeline::ChunkDecoding> decoding;    // recorder or decoder, whichever the link has now

  const pipeline::LinkDecoder& current_decoder() const { return recorder ? recorder->decoder() : *decoder; }
  void retire_decoder() {
    if (!recorder && !decoder) return;
    for (const auto& [layer, counters] : current_decoder().counters()) retired[layer] += counters;
    recorder.reset();
    decoder.reset();
    clock_epochs.clear();  // a new decoder counts restarts from 0
  }
};

// A link's chunks through its recorder while recording, else through its decoder. A store that fails mid-chunk ends
// the recording (the links go on): that chunk is decoded again without it, so its samples still reach the sinks.
class Daemon::LinkDecoding final : public pipeline::ChunkDecoding {
 public:
  LinkDecoding(Daemon& daemon, Link& link) : daemon_(daemon), link_(link) {}
  void decode(std::span<const std::uint8_t> bytes, std::int64_t recv_mono_ns, std::int64_t recv_wall_ns,
              std::vector<protocol::Sample>& out) override {
    if (link_.recorder) {
      try {
        link_.recorder->on_chunk(bytes, recv_mono_ns, recv_wall_ns, out);
        return;
      } catch (const store::StoreError& e) {
        daemon_.stop_recording(daemon_.stopping_here(e.what()));
        out.clear();
      }
    }
    link_.decoder->feed(bytes, recv_mono_ns, out);
  }
  void finish(std::int64_t mono_ns, std::int64_t wall_ns, std::vector<protocol::Sample>& out) override {
    if (link_.recorder) {
      link_.recorder->finish(mono_ns, wall_ns, out);
    } else {
      link_.decoder->finish(mono_ns, out);
    }
  }

 private:
  Daemon& daemon_;
  Link& link_;
};

// The daemon's own sink, first in line: each link's counts, a device restart said once, and the estimates into the
// live run while recording.
class Daemon::RecordingSink final : public pipeline::SessionSink {
 public:
  explicit RecordingSink(Daemon& daemon) : daemon_(daemon) {}
  void on_sample(std::size_t index, const protocol::Sample& sample, std::span<const store::Estimate> estimates,
                 std::int64_t) override {
    Link& link = *daemon_.links_[index];
    ++link.samples;
    if (std::uint32_t& epoch = link.clock_epochs[sample.link_id]; sample.clock_epoch != epoch) {
      epoch = sample.clock_epoch;
      spdlog::warn("link '{}': the device restarted (its sequence number and clock went back); estimating from its "
                   "new clock",
                   link.config.name);
    }
    for (const store::Estimate& estimate : estimates) {
      ++link.estimates;
      daemon_.record([&](Recording& r) { r.store.append_estimate(r.run, estimate); });
    }
  }

 private:
  Daemon& daemon_;
};

Daemon::Daemon(Config config, std::optional<fs::path> config_file)
    : config_(std::move(config)),
      config_file_(std::move(config_file)),
      params_(config_.params ? estimator::load_params(*config_.params) : estimator::ModelParams{}),
      signals_(io_, SIGINT, SIGTERM, SIGHUP),
      commit_timer_(io_),
      stats_timer_(io_),
      watchdog_timer_(io_),
      resume_timer_(io_) {
  signals_.add(SIGUSR1);
  // Each link's declared IMU axes; XBee radios while not recording (pipeline::is_unrecorded_radio_id) take their
  // link's. Detection reports once per link: a declaration the data contradict is logged and recorded as an event.
  pipeline::StageAxes axes;
  axes.declared = [this](std::uint32_t id) {
    const std::size_t i =
        pipeline::is_unrecorded_radio_id(id) ? pipeline::unrecorded_radio_link_index(id) : links_.size();
    for (std::size_t k = 0; k < links_.size(); ++k) {
      if (k == i || (i == links_.size() && links_[k]->store_link == static_cast<std::int64_t>(id))) {
        return estimator::parse_imu_axes(links_[k]->config.axes);  // checked when the config was read
      }
    }
    return estimator::auto_axes();
  };
  axes.on_resolved = [this](std::uint32_t id, const estimator::AxesResolution& resolution) {
    spdlog::info("link {}: {}", id, resolution.description);
    if (resolution.note) spdlog::info("link {}: {}", id, *resolution.note);
    if (!resolution.mismatch) return;
    spdlog::warn("link {}: {}", id, *resolution.mismatch);
    const std::int64_t link =
        pipeline::is_unrecorded_radio_id(id) ? links_[pipeline::unrecorded_radio_link_index(id)]->store_link : id;
    record([&](Recording& r) {
      r.store.append_event(r.session, {.link_id = link,
                                       .mono_ns = mono_now_ns(),
                                       .wall_ns = wall_now_ns(),
                                       .kind = "imu_axes_mismatch",
                                       .detail = *resolution.mismatch});
    });
  };
  // Bad parameters fail here, before any I/O.
  engine_ = std::make_unique<pipeline::SessionEngine>(
      std::make_unique<pipeline::EstimationStage>(params_, std::move(axes)));
  outputs_ = std::make_unique<Outputs>(io_, config_.outputs);
  for (const LinkConfig& link_config : config_.links) {
    auto link = std::make_unique<Link>();
    Link& l = *link;
    l.index = links_.size();
    l.config = link_config;
    l.decoding = std::make_unique<LinkDecoding>(*this, l);
    l.store_link = static_cast<std::int64_t>(links_.size()) + 1;  // distinct until a recording assigns its own
    l.port = std::make_unique<SerialLink>(
        io_, link_config,
        SerialLink::Handlers{
            .on_data = [this, &l](std::span<const std::uint8_t> bytes) { on_data(l, bytes); },
            .on_open = [this, &l](const std::string& path, bool reopened) { on_open(l, path, reopened); },
            .on_lost = [this, &l](const std::string& reason) { on_lost(l, reason); }});
    if (!link_config.bridge.empty()) {
      l.bridge = std::make_unique<LinkBridge>(
          io_, link_config.bridge, [this, &l](std::span<const std::uint8_t> bytes) { write_to_link(l, bytes); });
    }
    if (link_config.feedback.enabled) l.feedback.emplace(link_config.format, link_config.feedback);
    links_.push_back(std::move(link));
  }
  sinks_.push_back(std::make_unique<RecordingSink>(*this));
  std::vector<LiveLink> live;
  for (auto& link : links_) {
    live.push_back({.name = link->config.name,
                    .feedback = link->feedback ? &*link->feedback : nullptr,
                    .bridge = link->bridge.get(),
                    .write = [this, &l = *link](std::span<const std::uint8_t> bytes) { write_to_link(l, bytes); }});
  }
  for (auto& sink : make_live_sinks(*outputs_, live)) sinks_.push_back(std::move(sink));
  for (auto& sink : sinks_) engine_->add_sink(*sink);
  if (auto problem = storage_problem()) {
    spdlog::error("not recording: {}", *problem);
    not_recording_ = NotRecording{.path = config_.store.path, .previous = "", .reason = *problem};
    use_decoders();
  } else {
    open_recording(config_.store.path, "");  // a store that cannot be opened at start is fatal
  }
}

Daemon::~Daemon() = default;

int Daemon::run() {
  for (auto& link : links_) link->port->start();
  wait_for_signal();
  every(commit_timer_, config_.store.commit_interval, &Daemon::commit_tick);
  every(stats_timer_, config_.stats_interval, &Daemon::stats_tick);
  every(resume_timer_, kStorageRetryInterval, &Daemon::resume_tick);
  // From the event loop, so a loop stuck for WatchdogSec is what systemd restarts.
  if (auto period = systemd_.watchdog_period()) every(watchdog_timer_, *period, &Daemon::watchdog_tick);
  systemd_.ready(status_line());
  spdlog::info("running: {}", status_line());
  io_.run();
  return 0;
}

void Daemon::stop() {
  boost::asio::post(io_, [this] { shutdown(); });
}

// --- Recording ---------------------------------------------------------------------------------------------------

void Daemon::open_recording(const fs::path& path, const std::string& note) {
  auto r = std::make_unique<Recording>(path, config_.store);
  const std::int64_t wall = wall_now_ns();
  std::vector<pipeline::SessionLink> links;
  std::string source = "imubridge run:";
  for (const auto& link : links_) {
    const LinkConfig& c = link->config;
    links.push_back({.recorded = {c.name, c.format, c.calibration, c.axes},
                     .device = fmt::format("{} @ {} baud", describe(c.device), c.baud)});
    source += fmt::format(" {} {} ({} @ {} baud);", c.name, describe(c.device), protocol::wire_format_name(c.format),
                          c.baud);
  }
  source.pop_back();
  // Sessions a killed or crashed daemon left open in this file: ended, as interrupted, before ours begins.
  for (const store::InterruptedSession& s : r->store.end_interrupted_sessions()) {
    spdlog::warn(
        "session {} in {} was left open by process {}, which has ended: marked interrupted at its last "
        "stored time",
        s.session, path.string(), s.writer.pid);
  }
  pipeline::RecordedSession begun = pipeline::begin_recorded_session(
      r->store,
      {.kind = "live",
       .source = source,
       .config = {{"imubridge_run", to_toml(config_)}},
       .started_wall_ns = wall,
       .note = note,
       .note_mono_ns = mono_now_ns(),
       .estimated_with = params_},
      links);
  r->session = begun.id;
  r->run = *begun.run;
  // Nothing below throws: every link switches to the new file, or (above) none does.
  for (std::size_t i = 0; i < links_.size(); ++i) {
    links_[i]->retire_decoder();
    links_[i]->store_link = begun.store_links[i];
    links_[i]->recorder = std::move(begun.recorders[i]);
  }
  // Link ids are the new file's: estimator state keyed by the old ones would never be used again.
  engine_->replace_stage(std::make_unique<pipeline::EstimationStage>(params_, *engine_->stage().axes()));
  spdlog::info("recording session {} into {}{}{}", r->session, path.string(),
               config_.params ? " with parameters from " + config_.params->string()
                              : " (no parameters: velocity is not estimated)",
               note.empty() ? "" : "; " + note);
  recording_ = std::move(r);
  not_recording_.reset();
}

// Ends the session as cleanly as the store still allows. The decoders' last frames are recorded and estimated (they
// come too late for the outputs).
void Daemon::close_recording() {
  if (!recording_) return;
  std::unique_ptr<Recording> r = std::move(recording_);  // from here on record() writes nothing
  const std::int64_t mono = mono_now_ns(), wall = wall_now_ns();
  std::vector<protocol::Sample> tail;
  try {
    for (auto& link : links_) {
      tail.clear();
      link->recorder->finish(mono, wall, tail);
      std::vector<store::Estimate> estimates;
      for (const auto& sample : tail) engine_->stage().update(sample, estimates);
      engine_->stage().finish(estimates);  // links still waiting for their axes
      for (const auto& estimate : estimates) r->store.append_estimate(r->run, estimate);
    }
    pipeline::end_recorded_session(r->store, r->session, wall);
    spdlog::info("session {} in {} ended", r->session, r->path.string());
  } catch (const store::StoreError& e) {
    spdlog::warn("session {} in {} could not be ended cleanly: {}", r->session, r->path.string(), e.what());
  }
  use_decoders();
}

void Daemon::use_decoders() {
  for (std::uint32_t i = 0; i < links_.size(); ++i) {
    Link& link = *links_[i];
    if (link.decoder) continue;
    link.retire_decoder();
    // Each XBee radio gets a link id of its own, above any store link's, so no estimator mixes two vehicles.
    link.decoder = std::make_unique<pipeline::LinkDecoder>(
        link.config.format, static_cast<std::uint32_t>(link.store_link), link.config.calibration,
        [radios = std::map<std::uint64_t, std::uint32_t>(), i](std::uint64_t source64) mutable {
          const auto id = pipeline::unrecorded_radio_id(i, static_cast<std::uint32_t>(radios.size()));
          return radios.try_emplace(source64, id).first->second;
        });
  }
}

void Daemon::stop_recording(NotRecording why) {
  spdlog::error("recording stopped: {}; links and outputs go on", why.reason);
  const bool steady = recording_ && Clock::now() - recording_->since >= kSteadyRecording;
  failures_in_a_row_ = steady ? 1 : failures_in_a_row_ + 1;
  next_resume_ = Clock::now() + resume_delay(failures_in_a_row_);
  close_recording();
  not_recording_ = std::move(why);
  systemd_.status(status_line());
}

Daemon::NotRecording Daemon::stopping_here(const std::string& reason, bool resumes) const {
  return {.path = recording_->path, .previous = recording_->name(), .reason = reason, .resumes = resumes};
}

void Daemon::resume_tick() {
  if (recording_ || !not_recording_ || !not_recording_->resumes || Clock::now() < next_resume_) return;
  const std::uint64_t wanted = config_.store.min_free_bytes + resume_margin(config_.store.min_free_bytes);
  if (auto free = free_bytes(); free && *free < wanted) return;
  const NotRecording why = *not_recording_;  // open_recording() clears it
  const std::string note = why.previous.empty() ? "starts late: at start " + why.reason
                                                : "resumes after " + why.previous + ", which stopped: " + why.reason;
  try {
    open_recording(why.path, note);  // a disk still full fails here, and is tried again at the next tick
  } catch (const store::StoreError& e) {
    spdlog::debug("recording cannot resume yet: {}", e.what());
    next_resume_ = Clock::now() + resume_delay(++failures_in_a_row_);
    return;
  }
  systemd_.status(status_line());
}

void Daemon::rotate() {
  const fs::path next = rotated_path(config_.store.path);
  const std::string previous = recording_->name();
  spdlog::info("{} reached store.max_size_mib ({}): continuing in {}", recording_->path.string(),
               mib(config_.store.max_size_bytes), next.string());
  record([&](Recording& r) {
    r.store.append_event(r.session, {.mono_ns = mono_now_ns(),
                                     .wall_ns = wall_now_ns(),
                                     .kind = "note",
                                     .detail = "continued in " + next.filename().string() + " (store.max_size_mib)"});
  });
  if (!recording_) return;  // that write failed: recording has stopped
  close_recording();
  ++rotations_;
  if (auto problem = storage_problem()) {
    return stop_recording({.path = next, .previous = previous, .reason = *problem});
  }
  try {
    open_recording(next, "continues " + previous);
  } catch (const store::StoreError& e) {
    stop_recording({.path = next, .previous = previous, .reason = e.what()});
  }
}

std::optional<std::uint64_t> Daemon::free_bytes() const {
  const fs::path dir = fs::absolute(config_.store.path).parent_path();
  struct statvfs vfs {};
  if (::statvfs(dir.c_str(), &vfs) != 0) return std::nullopt;  // a missing directory: opening the store says so
  return static_cast<std::uint64_t>(vfs.f_bavail) * vfs.f_frsize;
}

std::optional<std::string> Daemon::storage_problem() const {
  const auto free = free_bytes();
  if (!free || *free >= config_.store.min_free_bytes) return std::nullopt;
  return fmt::format("only {} free on {}, below store.min_free_mib ({})", mib(*free),
                     fs::absolute(config_.store.path).parent_path().string(), mib(config_.store.min_free_bytes));
}

void Daemon::check_storage() {
  if (!recording_) return;
  if (auto problem = storage_problem()) return stop_recording(stopping_here(*problem));
  const std::uint64_t cap = config_.store.max_size_bytes;
  if (cap == 0 || database_size(recording_->path) < cap) return;
  if (config_.store.on_full == StoreConfig::OnFull::rotate) return rotate();
  // Resuming would find the file at its cap again.
  stop_recording(stopping_here(fmt::format("{} reached store.max_size_mib ({})", recording_->path.string(), mib(cap)),
                               /*resumes=*/false));
}

template <typename Write>
void Daemon::record(Write&& write) {
  if (!recording_) return;
  try {
    write(*recording_);
  } catch (const store::StoreError& e) {
    stop_recording(stopping_here(e.what()));
  }
}

// --- Links -------------------------------------------------------------------------------------------------------

void Daemon::on_open(Link& link, const std::string& path, bool reopened) {
  const std::int64_t mono = mono_now_ns();
  std::string detail = path;
  if (reopened && link.lost_at_ns) detail += fmt::format(" after {:.1f} s", (mono - *link.lost_at_ns) * 1e-9);
  record([&](Recording& r) {
    r.store.append_event(r.session, {.link_id = link.store_link,
                                     .mono_ns = mono,
                                     .wall_ns = wall_now_ns(),
                                     .kind = reopened ? "reconnect" : "connected",
                                     .detail = detail});
  });
  systemd_.status(status_line());
}

void Daemon::on_lost(Link& link, const std::string& reason) {
  link.lost_at_ns = mono_now_ns();
  record([&](Recording& r) {
    r.store.append_event(r.session, {.link_id = link.store_link,
                                     .mono_ns = *link.lost_at_ns,
                                     .wall_ns = wall_now_ns(),
                                     .kind = "link_lost",
                                     .detail = reason});
  });
  systemd_.status(status_line());
}

void Daemon::on_data(Link& link, std::span<const std::uint8_t> bytes) {
  engine_->on_chunk(link.index, *link.decoding, bytes, mono_now_ns(), wall_now_ns());
  record([&](Recording& r) { commits_ += r.store.commit_if_due(Clock::now()); });
}

// Bytes for the vehicle (velocity feedback, a ground-control station's commands) are recorded as tx chunks.
void Daemon::write_to_link(Link& link, std::span<const std::uint8_t> bytes) {
  if (!link.port->write(bytes)) return;
  ++link.tx_chunks;
  record([&](Recording& r) {
    r.store.append_chunk(r.session, link.store_link, store::Direction::tx, mono_now_ns(), wall_now_ns(), bytes);
  });
}

// --- Operations --------------------------------------------------------------------------------------------------

void Daemon::wait_for_signal() {
  signals_.async_wait([this](const boost::system::error_code& ec, int signal) {
    if (ec) return;
    if (signal == SIGHUP) {
      reload();
    } else if (signal == SIGUSR1) {
      log_stats();
    } else {
      spdlog::info("{}: stopping", signal == SIGINT ? "SIGINT" : "SIGTERM");
      return shutdown();
    }
    wait_for_signal();
  });
}

// SIGHUP: the outputs, logging and free-space settings of the configuration file take effect, and the log file is
// reopened (after logrotate moved it). Links and the rest of the store keep running as they are: changing them needs
// a restart.
void Daemon::reload() {
  if (config_file_) {
    try {
      const Config fresh = load_config(*config_file_);
      outputs_->reconfigure(fresh.outputs);
      config_.outputs = fresh.outputs;
      config_.log_level = fresh.log_level;
      config_.log_file = fresh.log_file;
      config_.store.min_free_bytes = fresh.store.min_free_bytes;  // the next check of free space applies it
    } catch (const std::exception& e) {
      spdlog::error("SIGHUP: {}; keeping the running configuration", e.what());
    }
  }
  try {
    configure_logging(config_);
  } catch (const spdlog::spdlog_ex& e) {
    spdlog::error("SIGHUP: cannot reopen the log: {}", e.what());
  }
  spdlog::info("SIGHUP: reloaded {}", config_file_ ? config_file_->string() : "the log (no configuration file)");
}

void Daemon::every(boost::asio::steady_timer& timer, std::chrono::nanoseconds period, void (Daemon::*tick)()) {
  timer.expires_after(period);
  timer.async_wait([this, &timer, period, tick](const boost::system::error_code& ec) {
    if (ec) return;  // cancelled: stopping
    (this->*tick)();
    every(timer, period, tick);
  });
}

void Daemon::commit_tick() {
  record([&](Recording& r) {
    if (r.store.pending_rows() > 0) {
      r.store.commit();
      ++commits_;
    }
  });
  check_storage();
}

void Daemon::stats_tick() {
  log_stats();
  systemd_.status(status_line());
}

void Daemon::log_stats() const { spdlog::info("stats {}", counters().dump()); }

void Daemon::watchdog_tick() { systemd_.watchdog(); }

void Daemon::shutdown() {
  if (stopping_) return;
  stopping_ = true;
  systemd_.stopping();
  for (auto& link : links_) link->port->stop();
  boost::system::error_code ignored;
  signals_.cancel(ignored);
  commit_timer_.cancel();
  stats_timer_.cancel();
  watchdog_timer_.cancel();
  resume_timer_.cancel();
  close_recording();
  log_stats();
  io_.stop();
}

std::string Daemon::status_line() const {
  std::string status =
      recording_ ? fmt::format("recording session {} into {}", recording_->session, recording_->path.string())
      : not_recording_
          ? fmt::format(
                "not recording: {}; links and outputs go on{}", not_recording_->reason,
                not_recording_->resumes
                    ? fmt::format(" (resumes once {} is free)",
                                  mib(config_.store.min_free_bytes + resume_margin(config_.store.min_free_bytes)))
                    : "")
          : std::string("not recording");
  for (const auto& link : links_) {
    status += fmt::format("; {} {} ({} samples)", link->config.name,
                          link->port->is_open() ? link->port->path() : "waiting for " + describe(link->config.device),
                          link->samples);
  }
  return status;
}

nlohmann::json Daemon::counters() const {
  nlohmann::json links = nlohmann::json::object();
  for (const auto& link : links_) {
    const SerialLink::Counters& port = link->port->counters();
    nlohmann::json decoders = nlohmann::json::object();
    std::map<std::string, protocol::DecoderCounters> totals = link->retired;
    for (const auto& [layer, counters] : link->current_decoder().counters()) totals[layer] += counters;
    for (const auto& [layer, counters] : totals) decoders[layer] = counters;
    nlohmann::json j{{"device", link->port->is_open() ? nlohmann::json(link->port->path()) : nlohmann::json()},
                     {"bytes_read", port.bytes_read},
                     {"reads", port.reads},
                     {"decoders", decoders},
                     {"samples", link->samples},
                     {"estimates", link->estimates},
                     {"opens", port.opens},
                     {"losses", port.losses},
                     {"failed_opens", port.failed_opens},
                     {"tx",
                      {{"chunks", link->tx_chunks},
                       {"bytes_written", port.bytes_written},
                       {"bytes_dropped", port.bytes_dropped_tx},
                       {"queue_bytes", port.tx_queue_bytes}}}};
    if (link->bridge) j["bridge"] = link->bridge->counters();
    if (link->feedback) j["feedback"] = link->feedback->counters();
    links[link->config.name] = std::move(j);
  }
  nlohmann::json store{{"recording", recording_ != nullptr}, {"commits", commits_}, {"rotations", rotations_}};
  if (recording_) {
    store["path"] = recording_->path.string();
    store["session"] = recording_->session;
    store["pending_rows"] = recording_->store.pending_rows();
    store["size_bytes"] = database_size(recording_->path);
  }
  return {{"links", links}, {"store", store}, {"outputs", outputs_->counters()}};
}

}  // namespace imubridge::daemon
