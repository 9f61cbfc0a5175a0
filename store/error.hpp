#pragma once
// The one exception the store throws. Its message is one line naming the file and what failed, fit to show a user.
#include <stdexcept>
#include <string>

namespace imubridge::store {

class StoreError : public std::runtime_error {
 public:
  // `sqlite_code` is SQLite's primary result code (SQLITE_FULL, SQLITE_BUSY, ...) when SQLite reported the failure,
  // 0 when the store found it (a newer schema, an unknown session), so callers can tell a full disk from a bug.
  explicit StoreError(const std::string& message, int sqlite_code = 0)
      : std::runtime_error(message), sqlite_code_(sqlite_code) {}

  int sqlite_code() const noexcept { return sqlite_code_; }

 private:
  int sqlite_code_;
};

}  // namespace imubridge::store
