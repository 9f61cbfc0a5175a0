#pragma once
// The daemon's private parts, shared by daemon.cpp (construction, links, the event loop, operations) and
// recording.cpp (sessions, rotation, free space and resuming): not for use outside daemon/.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "daemon/bridge.hpp"
#include "daemon/daemon.hpp"
#include "daemon/serial_link.hpp"
#include "daemon/vehicle_feedback.hpp"
#include "pipeline/land_detector.hpp"
#include "pipeline/link_recorder.hpp"
#include "pipeline/session_engine.hpp"
#include "store/store.hpp"

namespace imubridge::daemon {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
constexpr double kMiB = 1024.0 * 1024.0;
// While not recording, free space is looked at this often; recording resumes once there is min_free_mib plus
// kResumeMargin (a tenth of min_free_mib, at least kMinResumeMargin) free, so usage hovering at the floor does not
// start and stop a session at every check.
constexpr auto kStorageRetryInterval = std::chrono::seconds(5);
constexpr std::uint64_t kMinResumeMargin = 16ull << 20;
inline std::uint64_t resume_margin(std::uint64_t min_free_bytes) {
  return std::max(kMinResumeMargin, min_free_bytes / 10);
}

inline std::int64_t mono_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
}
inline std::int64_t wall_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

inline std::string mib(std::uint64_t bytes) { return fmt::format("{:.1f} MiB", static_cast<double>(bytes) / kMiB); }

// The database and its write-ahead log: SQLite moves pages from one to the other at checkpoints.
std::uint64_t database_size(const fs::path& path);

struct Daemon::Recording {
  Recording(const fs::path& file, const StoreConfig& config)
      : path(file),
        store(file, store::StoreOptions{.commit_interval = config.commit_interval,
                                        .background_checkpoint = std::chrono::seconds(1)}) {}
  fs::path path;
  store::Store store;
  std::int64_t session = 0;
  std::vector<std::int64_t> store_links;  // by link index
  // The engine's sink that stores what it hears; the daemon's RecordingSink hands it on while recording.
  std::unique_ptr<pipeline::SessionRecording> sink;
  Clock::time_point since = Clock::now();

  // As notes name it in the session that continues it: "imubridge.db session 4".
  std::string name() const { return fmt::format("{} session {}", path.filename().string(), session); }
};

struct Daemon::Link {
  std::size_t index = 0;  // in links_, and the engine's link number (protocol::SourceKey::link)
  LinkConfig config;
  std::unique_ptr<SerialLink> port;
  std::unique_ptr<LinkBridge> bridge;
  std::optional<VehicleFeedback> feedback;
  std::uint64_t samples = 0, estimates = 0, tx_chunks = 0;
  std::optional<std::int64_t> lost_at_ns;
  std::optional<protocol::mavlink::ImuSource> logged_imu;  // the IMU a MAVLink link locked on, once logged
  pipeline::MavlinkLandDetectorChanges land_detector;      // logged as it changes
  // A MAVLink link's vehicle (system, component) once heard: the IMU's sender, else the first other than us. Stream
  // requests target it; before it is heard they are broadcast (0, 0).
  std::optional<std::pair<std::uint8_t, std::uint8_t>> vehicle;
  std::uint8_t gcs_seq = 0;                                   // our frames' sequence numbers
  std::map<protocol::SourceKey, std::uint32_t> clock_epochs;  // by sample stream (an XBee link has one per radio)
};

template <typename Write>
void Daemon::record(Write&& write) {
  if (!recording_) return;
  try {
    write(*recording_);
  } catch (const store::StoreError& e) {
    stop_recording(stopping_here(e.what()));
  }
}

}  // namespace imubridge::daemon
