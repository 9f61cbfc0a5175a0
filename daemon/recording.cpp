// Recording: a session begun in the configured file and ended, rotated into a new file at max_size_mib, stopped by a
// failing store or short free space, and resumed once it can be (docs/operations.md, "Recording").
#include <sys/statvfs.h>

#include <algorithm>
#include <ctime>

#include "daemon/config_file.hpp"
#include "daemon/daemon_internal.hpp"
#include "daemon/port_list.hpp"
#include "pipeline/recorded_session.hpp"

namespace imubridge::daemon {
namespace {

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

}  // namespace

std::uint64_t database_size(const fs::path& path) {
  std::error_code ec;
  std::uint64_t size = 0;
  for (const fs::path& file : {path, fs::path(path.string() + "-wal")}) {
    const auto n = fs::file_size(file, ec);
    if (!ec) size += n;
  }
  return size;
}

void Daemon::open_recording(const fs::path& path, const std::string& note) {
  auto r = std::make_unique<Recording>(path, config_.store);
  const std::int64_t wall = wall_now_ns();
  std::vector<pipeline::SessionLink> links;
  std::string source = "imubridge run:";
  for (const auto& link : links_) {
    const LinkConfig& c = link->config;
    // A MAVLink link that has locked on its IMU keeps to it in the new session (a rotation, a resumed recording),
    // recorded as that IMU; else the session records the rule it will lock by.
    const auto locked = engine_->decoder(link->index).mavlink_imu();
    links.push_back({.recorded = {.name = c.name,
                                  .format = c.format,
                                  .calibration = c.calibration,
                                  .imu_axes = c.axes,
                                  .mavlink_imu = locked,
                                  .mavlink_imu_lock = locked ? std::nullopt : mavlink_imu_lock(c)},
                     .device = fmt::format("{} @ {} baud", describe(c.device), c.baud),
                     .mavlink_reference = c.format == protocol::WireFormat::mavlink
                                              ? std::optional(pipeline::MavlinkReference::Choice{})
                                              : std::nullopt});
    source +=
        fmt::format(" {} {} ({} @ {} baud);", c.name, describe(c.device), protocol::wire_format_name(c.format), c.baud);
  }
  source.pop_back();
  // Sessions a killed or crashed daemon left open in this file: ended, as interrupted, before ours begins.
  for (const store::InterruptedSession& s : r->store.end_interrupted_sessions()) {
    spdlog::warn(
        "session {} in {} was left open by process {}, which has ended: marked interrupted at its last "
        "stored time",
        s.session, path.string(), s.writer.pid);
  }
  pipeline::RecordedSession begun = pipeline::begin_recorded_session(r->store,
                                                                     {.kind = "live",
                                                                      .source = source,
                                                                      .config = {{"imubridge_run", to_toml(config_)}},
                                                                      .started_wall_ns = wall,
                                                                      .note = note,
                                                                      .note_mono_ns = mono_now_ns(),
                                                                      .estimated_with = params_},
                                                                     links);
  // Nothing below throws: the recording begins, or (above) nothing does. The decoders and filters run on: what
  // they hear from now on goes to the new file's store links.
  r->session = begun.id;
  r->store_links = begun.store_links;
  r->sink = std::make_unique<pipeline::SessionRecording>(r->store, begun, links, *engine_);
  spdlog::info("recording session {} into {}{}{}", r->session, path.string(),
               config_.params ? " with parameters from " + config_.params->string()
                              : " (no parameters: velocity is not estimated)",
               note.empty() ? "" : "; " + note);
  recording_ = std::move(r);
  not_recording_.reset();
}

// Ends the session as cleanly as the store still allows: each link's counters and reference rows so far (the
// decoders go on; at shutdown they have finished first, their last samples recorded).
void Daemon::close_recording() {
  if (!recording_) return;
  std::unique_ptr<Recording> r = std::move(recording_);  // from here on record() writes nothing
  try {
    r->sink->end(*engine_, mono_now_ns(), wall_now_ns());
    pipeline::end_recorded_session(r->store, r->session, wall_now_ns());
    spdlog::info("session {} in {} ended", r->session, r->path.string());
  } catch (const store::StoreError& e) {
    spdlog::warn("session {} in {} could not be ended cleanly: {}", r->session, r->path.string(), e.what());
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

}  // namespace imubridge::daemon
