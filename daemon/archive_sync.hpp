#pragma once
// The daemon's [sync]: its store copied into the fleet archive every interval_s, on a thread of its own with its own
// read-only SQLite connection (archive/sync.hpp), so recording never waits for PostgreSQL or the network. A pass
// that fails (the server or the network gone) is logged in one line and tried again with a growing delay, on a new
// connection; what was committed stays, and the next pass goes on from there. docs/config.md, [sync].
#include <condition_variable>
#include <filesystem>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "archive/pg_connection.hpp"
#include "daemon/config.hpp"

namespace imubridge::daemon {

// The store files of a station: the configured one, and the ones a rotation continued in beside it
// (imubridge-20240521-143000.db), in name order (their time, to the second). Only those that exist.
std::vector<std::filesystem::path> station_store_files(const std::filesystem::path& store_path);
// A file's name in the archive: the station for the configured file, "station/imubridge-20240521-143000" for a
// rotated one, whose session ids start at 1 again.
std::string archive_station(const std::string& station, const std::filesystem::path& store_path,
                            const std::filesystem::path& file);

class ArchiveSyncThread {
 public:
  // Starts syncing at once. The password (password_file or password_env) is read at each connection.
  ArchiveSyncThread(SyncConfig config, std::filesystem::path store_path);
  // Stops between two batches, breaking off a call to PostgreSQL under way (archive::PgConnection::interrupt), and
  // joins: the daemon's shutdown never waits for the network (a connection being opened: at most 5 s).
  ~ArchiveSyncThread();
  ArchiveSyncThread(const ArchiveSyncThread&) = delete;
  ArchiveSyncThread& operator=(const ArchiveSyncThread&) = delete;

 private:
  void run(std::stop_token stop);
  archive::PgConnectOptions connect_options() const;

  SyncConfig config_;
  std::filesystem::path store_path_;
  std::mutex mutex_;
  std::condition_variable_any wake_;
  archive::PgConnection* connection_ = nullptr;  // the thread's connection, for the destructor to interrupt; mutex_
  std::jthread thread_;                          // last: started once everything it uses is ready
};

}  // namespace imubridge::daemon
