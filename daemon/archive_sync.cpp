#include "daemon/archive_sync.hpp"

#include <spdlog/spdlog.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <memory>

#include "archive/sync.hpp"

namespace imubridge::daemon {
namespace {

namespace fs = std::filesystem;

// After a failed pass: interval_s (at most 5 s), doubling up to 5 minutes (or interval_s, if longer), so an archive
// down for a day costs a line every few minutes rather than a flood.
constexpr std::chrono::seconds kFirstRetry{5}, kLongestRetry{300};

}  // namespace

std::vector<fs::path> station_store_files(const fs::path& store_path) {
  std::vector<fs::path> files;
  std::error_code ec;
  if (fs::exists(store_path, ec)) files.push_back(store_path);
  const std::string prefix = store_path.stem().string() + "-", extension = store_path.extension().string();
  const fs::path directory = store_path.has_parent_path() ? store_path.parent_path() : fs::path(".");
  std::vector<fs::path> rotated;
  for (const auto& entry : fs::directory_iterator(directory, ec)) {
    const std::string name = entry.path().filename().string();
    if (entry.is_regular_file(ec) && name.starts_with(prefix) && entry.path().extension() == extension) {
      rotated.push_back(entry.path());
    }
  }
  std::sort(rotated.begin(), rotated.end());  // any order would do: each file is a station of its own
  files.insert(files.end(), rotated.begin(), rotated.end());
  return files;
}

std::string archive_station(const std::string& station, const fs::path& store_path, const fs::path& file) {
  if (file == store_path) return station;
  return station + "/" + file.stem().string();
}

ArchiveSyncThread::ArchiveSyncThread(SyncConfig config, fs::path store_path)
    : config_(std::move(config)),
      store_path_(std::move(store_path)),
      thread_([this](std::stop_token stop) { run(stop); }) {}

ArchiveSyncThread::~ArchiveSyncThread() {
  thread_.request_stop();  // wakes the wait below; a pass stops before its next batch
  {
    std::lock_guard lock(mutex_);
    if (connection_ != nullptr) connection_->interrupt();
  }
  thread_.join();
}

archive::PgConnectOptions ArchiveSyncThread::connect_options() const {
  archive::PgConnectOptions options{.url = config_.to, .connect_timeout_s = 5};
  if (config_.password_file) options.password = archive::read_password_file(config_.password_file->string());
  if (config_.password_env) {
    const char* value = std::getenv(config_.password_env->c_str());
    if (value == nullptr)
      throw archive::ArchiveError("the environment variable " + *config_.password_env +
                                  " (sync.password_env) is not set");
    options.password = value;
  }
  return options;
}

void ArchiveSyncThread::run(std::stop_token stop) {
  // Background work: on a busy core the recorder's thread goes first (Linux's nice is per thread).
  ::setpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()), 10);
  const std::string station = config_.station.empty() ? archive::default_station() : config_.station;
  const std::string archive_name = archive::redact_url(config_.to);
  std::unique_ptr<archive::PgConnection> pg;
  const std::chrono::seconds first_retry = std::min(config_.interval, kFirstRetry);
  std::chrono::seconds retry = first_retry;
  bool failing = false;
  spdlog::info("archive sync: {} into {} as station '{}', every {} s{}", store_path_.string(), archive_name, station,
               config_.interval.count(), config_.chunks ? ", with the raw chunks" : "");
  while (!stop.stop_requested()) {
    std::chrono::seconds wait = config_.interval;
    try {
      if (!pg) {
        pg = std::make_unique<archive::PgConnection>(connect_options());
        std::lock_guard lock(mutex_);
        connection_ = pg.get();
      }
      archive::SyncCounts total;
      for (const fs::path& file : station_store_files(store_path_)) {
        const auto counts = archive::sync_to_archive(file, *pg,
                                                     {.station = archive_station(station, store_path_, file),
                                                      .chunks = config_.chunks,
                                                      .stop_requested = [&] { return stop.stop_requested(); }});
        total.samples += counts.samples;
        total.estimates += counts.estimates;
        total.events += counts.events;
      }
      if (failing) spdlog::info("archive sync: {} reachable again", archive_name);
      failing = false;
      retry = first_retry;
      spdlog::debug("archive sync: {} samples, {} estimates, {} events into {} as station '{}'", total.samples,
                    total.estimates, total.events, archive_name, station);
    } catch (const std::exception& e) {
      {
        std::lock_guard lock(mutex_);
        connection_ = nullptr;
      }
      pg.reset();  // a new connection for the next pass: this one may be half-way through anything
      if (stop.stop_requested()) break;  // interrupted by the destructor: not a failure
      wait = retry;
      spdlog::warn("archive sync: {}; retrying in {} s", e.what(), retry.count());
      failing = true;
      retry = std::min(retry * 2, std::max(kLongestRetry, config_.interval));
    }
    std::unique_lock lock(mutex_);
    wake_.wait_for(lock, stop, wait, [] { return false; });
  }
  std::lock_guard lock(mutex_);
  connection_ = nullptr;  // pg goes with this frame
}

}  // namespace imubridge::daemon
