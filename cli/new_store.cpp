#include "cli/new_store.hpp"

#include <exception>
#include <stdexcept>
#include <string>
#include <system_error>

namespace imubridge::daemon {

NewStoreGuard::NewStoreGuard(std::filesystem::path db)
    : db_(std::move(db)), created_(!std::filesystem::exists(db_)), exceptions_(std::uncaught_exceptions()) {
  const std::filesystem::path folder = db_.has_parent_path() ? db_.parent_path() : ".";
  if (created_ && !std::filesystem::is_directory(folder)) {
    throw std::invalid_argument("no folder " + folder.string() + " for the store " + db_.string() +
                                ": give --db FILE, or create the folder");
  }
}

NewStoreGuard::~NewStoreGuard() {
  if (!created_ || std::uncaught_exceptions() <= exceptions_) return;
  std::error_code ignored;  // a destructor during unwinding must not throw: a file left is the old behaviour
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) {
    std::filesystem::remove(db_.string() + suffix, ignored);
  }
}

}  // namespace imubridge::daemon
