#include "store/wal_checkpointer.hpp"

#include "store/error.hpp"
#include "store/report.hpp"

namespace imubridge::store {

WalCheckpointer::WalCheckpointer(const std::filesystem::path& path, std::chrono::milliseconds interval)
    : name_(path.string()), interval_(interval) {
  if (sqlite3_open_v2(name_.c_str(), &db_, SQLITE_OPEN_READWRITE, nullptr) != SQLITE_OK) {
    const std::string message = name_ + ": cannot open for checkpointing: " + sqlite3_errmsg(db_);
    sqlite3_close(db_);
    throw StoreError(message);
  }
  // The recorder's commits take the write lock for moments only; wait those out rather than skip the checkpoint.
  sqlite3_busy_timeout(db_, 100);
  // A connection learns that the file is in WAL mode from its first read; until then a checkpoint does nothing.
  if (sqlite3_exec(db_, "SELECT count(*) FROM sqlite_master", nullptr, nullptr, nullptr) != SQLITE_OK) {
    const std::string message = name_ + ": cannot read for checkpointing: " + sqlite3_errmsg(db_);
    sqlite3_close(db_);
    throw StoreError(message);
  }
  thread_ = std::thread([this] { run(); });
}

WalCheckpointer::~WalCheckpointer() {
  {
    const std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_one();
  thread_.join();
  sqlite3_close(db_);
}

void WalCheckpointer::run() {
  std::unique_lock lock(mutex_);
  while (!wake_.wait_for(lock, interval_, [this] { return stopping_; })) {
    lock.unlock();
    checkpoint();
    lock.lock();
  }
}

void WalCheckpointer::checkpoint() {
  const std::lock_guard lock(checkpoint_mutex_);
  const int rc = sqlite3_wal_checkpoint_v2(db_, nullptr, SQLITE_CHECKPOINT_PASSIVE, nullptr, nullptr);
  const std::string error = rc == SQLITE_OK || rc == SQLITE_BUSY ? "" : sqlite3_errmsg(db_);
  // Said once per new failure, not every second: the recorder's own writes report a full disk as it happens.
  if (!error.empty() && error != last_error_) report(name_ + ": background checkpoint failed: " + error);
  last_error_ = error;
}

}  // namespace imubridge::store
