#pragma once
// Copies the write-ahead log back into the database file from a thread of its own, on a connection of its own.
// In WAL mode with synchronous=NORMAL a commit costs no fsync; the checkpoint does, and SQLite runs it in whichever
// connection's commit crosses wal_autocheckpoint: for the daemon that is its event loop, stalled 0.4-6 ms at every
// checkpoint while frames wait (docs/performance.md). A PASSIVE checkpoint never blocks the writer, so the recorder
// commits while the disk syncs here.
#include <sqlite3.h>

#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <mutex>
#include <string>
#include <thread>

namespace imubridge::store {

class WalCheckpointer {
 public:
  // Opens its connection at once (throws StoreError if it cannot) and checkpoints every `interval` until destroyed.
  WalCheckpointer(const std::filesystem::path& path, std::chrono::milliseconds interval);
  ~WalCheckpointer();  // stops the thread; the database's last connection to close checkpoints what is left
  WalCheckpointer(const WalCheckpointer&) = delete;
  WalCheckpointer& operator=(const WalCheckpointer&) = delete;

  // One checkpoint now, as the thread runs them. A failure (disk full) is reported through store::report() (the
  // daemon's log) once until it changes: it leaves the log growing but every committed row safe in it.
  void checkpoint();

 private:
  void run();

  sqlite3* db_ = nullptr;
  std::string name_;
  std::chrono::milliseconds interval_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stopping_ = false;
  std::mutex checkpoint_mutex_;  // the thread's checkpoints and checkpoint() calls take turns
  std::string last_error_;       // the last checkpoint's ("" when it succeeded), so a lasting failure is said once
  std::thread thread_;           // last: starts once everything above is ready
};

}  // namespace imubridge::store
