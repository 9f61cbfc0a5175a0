#pragma once
// A command that writes into a store it may create (import, sim --db) leaves no empty store behind when it fails:
// declare a NewStoreGuard before the Store. If the file did not exist and the command throws, the store's files are
// removed as the exception leaves the scope (the Store, declared after it, is closed first).
#include <filesystem>

namespace imubridge::daemon {

class NewStoreGuard {
 public:
  // Throws std::invalid_argument, a usage error, when the store's folder does not exist: a laptop has no
  // /var/lib/imubridge (the daemon's default), and SQLite's "unable to open database file" would not say so.
  explicit NewStoreGuard(std::filesystem::path db);
  NewStoreGuard(const NewStoreGuard&) = delete;
  NewStoreGuard& operator=(const NewStoreGuard&) = delete;
  ~NewStoreGuard();

 private:
  std::filesystem::path db_;
  bool created_;
  int exceptions_;  // in flight when constructed: more at destruction means a failure is unwinding
};

}  // namespace imubridge::daemon
