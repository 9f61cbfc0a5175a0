#include "store/sqlite.hpp"

#include <sqlite3.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <cstring>
#include <limits>
#include <system_error>
#include <utility>

namespace imubridge::store {
namespace {

// A second writer on the same file (rare: one daemon records a file) gets this long to finish its transaction.
constexpr int kBusyTimeoutMs = 1000;

std::string reason(int error_number) {
  std::string text = std::strerror(error_number);
  if (!text.empty()) text[0] = static_cast<char>(std::tolower(static_cast<unsigned char>(text[0])));
  return text;
}

// Why `path` cannot be the database, in the user's terms, or "" when nothing is visibly wrong. SQLite says "unable
// to open database file" for all of these, and opens a file it may not write read-only without a word, so that the
// first write fails far from the cause.
std::string unusable_because(const std::filesystem::path& path, bool read_only) {
  namespace fs = std::filesystem;
  const std::string& name = path.native();
  if (name.empty() || name == ":memory:" || name.starts_with("file:")) return "";  // not a plain file name
  std::error_code ec;
  if (fs::is_directory(path, ec)) return "is a directory, not a database file";
  const fs::path directory = path.has_parent_path() ? path.parent_path() : fs::path(".");
  if (!fs::exists(path, ec)) {
    if (!fs::is_directory(directory, ec)) {
      return "its directory " + directory.string() +
             (fs::exists(directory, ec) ? " is not a directory" : " does not exist");
    }
    if (read_only) return "";  // SQLite's "unable to open database file" says it
    if (::access(directory.c_str(), W_OK | X_OK) != 0) {
      return "cannot be created in " + directory.string() + " (" + reason(errno) + ")";
    }
    return "";
  }
  if (::access(name.c_str(), R_OK) != 0) return "not readable (" + reason(errno) + ")";
  if (read_only) return "";
  if (::access(name.c_str(), W_OK) != 0) return "not writable (" + reason(errno) + ")";
  // The write-ahead log and its index are files beside the database.
  if (::access(directory.c_str(), W_OK | X_OK) != 0) {
    return "its directory " + directory.string() + " is not writable (" + reason(errno) +
           "), and the write-ahead log is kept there";
  }
  return "";
}

}  // namespace

Database::Database(const std::filesystem::path& path, bool read_only) : name_(path.string()) {
  if (const std::string why = unusable_because(path, read_only); !why.empty()) {
    throw StoreError(name_ + ": " + why, SQLITE_CANTOPEN);
  }
  // NOMUTEX: a Store is used by one thread at a time, so SQLite's per-call locking would be pure overhead.
  const int flags =
      (read_only ? SQLITE_OPEN_READONLY : SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE) | SQLITE_OPEN_NOMUTEX;
  int rc = sqlite3_open_v2(name_.c_str(), &db_, flags, nullptr);
  if (rc == SQLITE_OK) rc = sqlite3_busy_timeout(db_, kBusyTimeoutMs);
  if (rc != SQLITE_OK) {
    StoreError failure = error(rc);
    sqlite3_close_v2(db_);  // open_v2 allocates a handle even when it fails
    throw failure;
  }
}

Database::Database(Database&& other) noexcept : name_(std::move(other.name_)), db_(std::exchange(other.db_, nullptr)) {}

Database::~Database() { sqlite3_close_v2(db_); }

void Database::exec(std::string_view sql) {
  while (!sql.empty()) {
    sqlite3_stmt* stmt = nullptr;
    const char* tail = nullptr;
    const int rc = sqlite3_prepare_v2(db_, sql.data(), static_cast<int>(sql.size()), &stmt, &tail);
    if (rc != SQLITE_OK) throw error(rc);
    sql.remove_prefix(static_cast<std::size_t>(tail - sql.data()));
    if (stmt == nullptr) continue;  // only whitespace or a comment was left
    int step_rc = SQLITE_ROW;
    while (step_rc == SQLITE_ROW) step_rc = sqlite3_step(stmt);
    sqlite3_finalize(stmt);  // keeps the connection's error message for error() below
    if (step_rc != SQLITE_DONE) throw error(step_rc);
  }
}

std::int64_t Database::query_int(std::string_view sql) const {
  Statement query(*this, sql);
  if (!query.step()) throw StoreError(name_ + ": no row from " + std::string(sql));
  return query.column_int(0);
}

bool Database::in_transaction() const noexcept { return sqlite3_get_autocommit(db_) == 0; }

void Database::rollback() noexcept {
  if (!in_transaction()) return;
  sqlite3_stmt* stmt = nullptr;
  if (sqlite3_prepare_v2(db_, "ROLLBACK", -1, &stmt, nullptr) == SQLITE_OK) sqlite3_step(stmt);
  sqlite3_finalize(stmt);
}

std::int64_t Database::last_insert_id() const noexcept { return sqlite3_last_insert_rowid(db_); }

std::int64_t Database::changes() const noexcept { return sqlite3_changes64(db_); }

StoreError Database::error(int rc) const {
  const char* message = db_ != nullptr ? sqlite3_errmsg(db_) : sqlite3_errstr(rc);
  return StoreError(name_ + ": " + message, rc & 0xff);
}

void Statement::Finalize::operator()(sqlite3_stmt* stmt) const noexcept { sqlite3_finalize(stmt); }

Statement::Statement(const Database& db, std::string_view sql) : db_(&db) {
  sqlite3_stmt* stmt = nullptr;
  // PERSISTENT: most statements live as long as their Store, so SQLite should not take them from its small-block pool.
  const int rc = sqlite3_prepare_v3(db.handle(), sql.data(), static_cast<int>(sql.size()), SQLITE_PREPARE_PERSISTENT,
                                    &stmt, nullptr);
  stmt_.reset(stmt);
  if (rc != SQLITE_OK) throw db.error(rc);
}

Statement& Statement::check_bind(int rc) {
  if (rc != SQLITE_OK) throw db_->error(rc);
  return *this;
}

Statement& Statement::bind_int(int index, std::int64_t value) {
  return check_bind(sqlite3_bind_int64(stmt_.get(), index, value));
}

Statement& Statement::bind_real(int index, double value) {
  return check_bind(sqlite3_bind_double(stmt_.get(), index, value));
}

// An empty view may have a null data(), which SQLite would store as NULL; "" keeps it an empty value.
Statement& Statement::bind_text(int index, std::string_view value) {
  return check_bind(sqlite3_bind_text64(stmt_.get(), index, value.empty() ? "" : value.data(), value.size(),
                                        SQLITE_STATIC, SQLITE_UTF8));
}

Statement& Statement::bind_blob(int index, std::span<const std::uint8_t> value) {
  static constexpr std::uint8_t kNothing = 0;
  return check_bind(
      sqlite3_bind_blob64(stmt_.get(), index, value.empty() ? &kNothing : value.data(), value.size(), SQLITE_STATIC));
}

Statement& Statement::bind_null(int index) { return check_bind(sqlite3_bind_null(stmt_.get(), index)); }

bool Statement::step() {
  const int rc = sqlite3_step(stmt_.get());
  if (rc == SQLITE_ROW) return true;
  sqlite3_reset(stmt_.get());  // repeats the step's error code, which we already hold
  if (rc != SQLITE_DONE) throw db_->error(rc);
  return false;
}

bool Statement::is_null(int column) const { return sqlite3_column_type(stmt_.get(), column) == SQLITE_NULL; }

std::int64_t Statement::column_int(int column) const { return sqlite3_column_int64(stmt_.get(), column); }

double Statement::column_real(int column) const {
  // A NULL reads as 0.0 (without changing the column's type), so only a 0.0 needs its type asked: a flight's reading
  // asks for millions of values, and the second call per value was a fifth of it.
  const double value = sqlite3_column_double(stmt_.get(), column);
  return value == 0.0 && is_null(column) ? std::numeric_limits<double>::quiet_NaN() : value;
}

std::string Statement::column_text(int column) const {
  const auto* text = reinterpret_cast<const char*>(sqlite3_column_text(stmt_.get(), column));
  return text == nullptr ? std::string()
                         : std::string(text, static_cast<std::size_t>(sqlite3_column_bytes(stmt_.get(), column)));
}

std::span<const std::uint8_t> Statement::column_blob(int column) const {
  const auto* data = static_cast<const std::uint8_t*>(sqlite3_column_blob(stmt_.get(), column));
  return {data, static_cast<std::size_t>(sqlite3_column_bytes(stmt_.get(), column))};
}

}  // namespace imubridge::store
