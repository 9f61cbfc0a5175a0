#pragma once
// RAII owner of a libpq connection, with the store's discipline for SQLite (store/sqlite.hpp): every call's result
// is checked, a failure becomes one ArchiveError line naming the server (never its password), and transactions are
// explicit. Rows go in and out with COPY, the fastest path PostgreSQL has for many rows.
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

struct pg_conn;
struct pg_result;

namespace imubridge::archive {

class ArchiveError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The URL as it can be shown: any password in it is replaced by "***".
std::string redact_url(std::string_view url);

// The password kept in `path`: its first line. Throws ArchiveError naming the file (never its content).
std::string read_password_file(const std::string& path);

// One result, freed when it goes. Rows and columns count from 0; values are PostgreSQL's text form.
class PgResult {
 public:
  explicit PgResult(pg_result* result) noexcept : result_(result) {}
  int rows() const noexcept;
  bool is_null(int row, int column) const noexcept;
  std::string text(int row, int column) const;
  std::int64_t integer(int row, int column) const;  // throws on NULL or a non-integer

 private:
  struct Clear {
    void operator()(pg_result* result) const noexcept;
  };
  std::unique_ptr<pg_result, Clear> result_;
};

struct PgConnectOptions {
  std::string url;                        // postgresql://user@host:port/db?... (libpq's connection URI or keywords)
  std::optional<std::string> password{};  // when not in the URL, PGPASSWORD or ~/.pgpass
  int connect_timeout_s = 10;             // unless the URL sets connect_timeout: a server gone never hangs us
  std::string application_name = "imubridge";
};

class PgConnection {
 public:
  // Connects, or throws ArchiveError "<url>: <libpq's reason>".
  explicit PgConnection(const PgConnectOptions& options);
  PgConnection(const PgConnection&) = delete;
  PgConnection& operator=(const PgConnection&) = delete;
  ~PgConnection();

  const std::string& name() const noexcept { return name_; }

  // Runs `sql` (one or more statements without parameters) and checks that it succeeded.
  void exec(std::string_view sql);
  // Runs one statement with text parameters ($1, $2, ...; nullopt is NULL) and returns its rows.
  PgResult query(std::string_view sql, const std::vector<std::optional<std::string>>& params = {});
  // COPY ... FROM STDIN with `data` in the format the statement names (copy_format.hpp), in the open transaction.
  void copy_in(std::string_view copy_sql, std::string_view data);
  // COPY ... TO STDOUT: each line (COPY's text format, without its newline) to `line`, in order.
  void copy_out(std::string_view copy_sql, const std::function<void(std::string_view line)>& line);

  // `value` as an SQL string literal, quoted and escaped for this connection (COPY takes no parameters).
  std::string literal(std::string_view value) const;

  // BEGIN ... COMMIT around `work`; ROLLBACK if it throws.
  template <typename Work>
  void transaction(Work&& work) {
    exec("BEGIN");
    try {
      work();
      exec("COMMIT");
    } catch (...) {
      rollback();
      throw;
    }
  }
  void rollback() noexcept;

  // From another thread: breaks off what the connection waits for (the server's answer to a COPY over a network that
  // went silent), so the call fails at once instead of after the TCP timeouts. The connection is useless afterwards.
  void interrupt() noexcept;

 private:
  [[noreturn]] void fail(std::string_view what, pg_result* result = nullptr) const;
  PgResult checked(pg_result* result, std::string_view what);

  std::string name_;  // the redacted URL, for messages
  pg_conn* conn_ = nullptr;
};

}  // namespace imubridge::archive
