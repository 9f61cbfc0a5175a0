#pragma once
// RAII owners of a SQLite connection and of a prepared statement. Every SQLite call's result code is checked, and a
// failure becomes a StoreError "<file>: <SQLite's message>" carrying the result code.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "store/error.hpp"

struct sqlite3;
struct sqlite3_stmt;

namespace imubridge::store {

class Database {
 public:
  // Opens `path` read-write, creating it if missing, or read-only: then SQLite itself refuses every write. A path
  // that cannot be the database is refused with the reason: a directory, a missing directory, a file this process
  // may not read (or, read-write, write), or a directory where the file or its write-ahead log cannot be created.
  Database(const std::filesystem::path& path, bool read_only);
  Database(Database&& other) noexcept;
  Database& operator=(Database&&) = delete;
  ~Database();

  const std::string& name() const noexcept { return name_; }
  sqlite3* handle() const noexcept { return db_; }

  // Runs every statement of `sql` to completion, discarding rows (schema scripts, PRAGMAs, BEGIN/COMMIT).
  void exec(std::string_view sql);
  // The first column of the first row of `sql`, as an integer (PRAGMA values, counts).
  std::int64_t query_int(std::string_view sql) const;

  bool in_transaction() const noexcept;
  // Rolls back the open transaction, if any. Never throws: after some errors SQLite has already rolled it back.
  void rollback() noexcept;
  std::int64_t last_insert_id() const noexcept;
  // Rows changed by the latest INSERT/UPDATE/DELETE.
  std::int64_t changes() const noexcept;

  // The StoreError for result code `rc` of the latest call on this connection.
  StoreError error(int rc) const;

 private:
  std::string name_;
  sqlite3* db_ = nullptr;
};

class Statement {
 public:
  Statement(const Database& db, std::string_view sql);

  // Parameters count from 1 (?1, ?2, ...). Text and blobs are not copied: they must stay alive until step() is done
  // with the statement, and every parameter is bound again before each use.
  Statement& bind_int(int index, std::int64_t value);
  Statement& bind_real(int index, double value);  // NaN binds as NULL: SQLite has no NaN
  Statement& bind_text(int index, std::string_view value);
  Statement& bind_blob(int index, std::span<const std::uint8_t> value);
  Statement& bind_null(int index);

  // Advances to the next row; true when one is ready. When the rows are exhausted it returns false and resets the
  // statement for its next use. On error it resets the statement and throws.
  bool step();

  // Columns of the current row count from 0.
  bool is_null(int column) const;
  std::int64_t column_int(int column) const;
  double column_real(int column) const;  // NULL reads as NaN
  std::string column_text(int column) const;
  std::span<const std::uint8_t> column_blob(int column) const;  // valid until the next step()

 private:
  struct Finalize {
    void operator()(sqlite3_stmt* stmt) const noexcept;
  };
  Statement& check_bind(int rc);

  const Database* db_;
  std::unique_ptr<sqlite3_stmt, Finalize> stmt_;
};

}  // namespace imubridge::store
