#include "archive/pg_connection.hpp"

#include <libpq-fe.h>
#include <sys/socket.h>

#include <charconv>
#include <fstream>
#include <utility>

namespace imubridge::archive {
namespace {

// libpq's messages end in a newline and some span lines ("...failed: Connection refused\n\tIs the server running
// ..."): one line, as every error of imubridge is.
std::string one_line(std::string_view message) {
  std::string line;
  bool space = false;
  for (char c : message) {
    if (c == '\n' || c == '\r' || c == '\t' || c == ' ') {
      space = !line.empty();
      continue;
    }
    if (space) line += ' ';
    space = false;
    line += c;
  }
  return line;
}

}  // namespace

std::string redact_url(std::string_view url) {
  std::string text(url);
  // postgresql://user:PASSWORD@host...
  if (const auto scheme = text.find("://"); scheme != std::string::npos) {
    const auto at = text.find('@', scheme + 3);
    const auto colon = text.find(':', scheme + 3);
    if (at != std::string::npos && colon != std::string::npos && colon < at) {
      text.replace(colon + 1, at - colon - 1, "***");
    }
  }
  // ...?password=PASSWORD&... and the keyword form password=PASSWORD
  for (std::size_t from = 0; (from = text.find("password=", from)) != std::string::npos;) {
    const std::size_t value = from + 9;
    std::size_t end = text.find_first_of("& ", value);
    if (end == std::string::npos) end = text.size();
    text.replace(value, end - value, "***");
    from = value + 3;
  }
  return text;
}

std::string read_password_file(const std::string& path) {
  std::ifstream in(path);
  std::string password;
  if (!in || !std::getline(in, password)) throw ArchiveError("cannot read the password file " + path);
  if (!password.empty() && password.back() == '\r') password.pop_back();
  return password;
}

void PgResult::Clear::operator()(pg_result* result) const noexcept { PQclear(result); }

int PgResult::rows() const noexcept { return PQntuples(result_.get()); }

bool PgResult::is_null(int row, int column) const noexcept { return PQgetisnull(result_.get(), row, column) != 0; }

std::string PgResult::text(int row, int column) const {
  return {PQgetvalue(result_.get(), row, column), static_cast<std::size_t>(PQgetlength(result_.get(), row, column))};
}

std::int64_t PgResult::integer(int row, int column) const {
  const std::string value = text(row, column);
  std::int64_t number = 0;
  const auto [end, ec] = std::from_chars(value.data(), value.data() + value.size(), number);
  if (is_null(row, column) || ec != std::errc() || end != value.data() + value.size()) {
    throw ArchiveError("the archive answered '" + value + "' where a number was expected");
  }
  return number;
}

PgConnection::PgConnection(const PgConnectOptions& options) : name_(redact_url(options.url)) {
  const std::string timeout = std::to_string(options.connect_timeout_s);
  // Keywords before dbname are defaults the URL may override. TCP keepalives and tcp_user_timeout: a server that
  // vanishes from the network mid-COPY (cable, Wi-Fi, a VPN down) fails the call within a minute instead of the
  // kernel's quarter of an hour of retransmissions.
  std::vector<const char*> keys{"connect_timeout",     "application_name", "keepalives",      "keepalives_idle",
                                "keepalives_interval", "keepalives_count", "tcp_user_timeout"};
  std::vector<const char*> values{timeout.c_str(), options.application_name.c_str(), "1", "10", "5", "3", "30000"};
  if (options.password) {
    keys.push_back("password");
    values.push_back(options.password->c_str());
  }
  keys.push_back("dbname");
  values.push_back(options.url.c_str());
  keys.push_back(nullptr);
  values.push_back(nullptr);
  conn_ = PQconnectdbParams(keys.data(), values.data(), /*expand_dbname=*/1);
  if (conn_ == nullptr) throw ArchiveError(name_ + ": out of memory connecting");
  if (PQstatus(conn_) != CONNECTION_OK) {
    const std::string why = one_line(PQerrorMessage(conn_));
    PQfinish(conn_);
    conn_ = nullptr;
    throw ArchiveError(name_ + ": " + why);
  }
  // Notices (a table that already exists, ...) are for people at a psql prompt, not for a daemon's log.
  PQsetNoticeProcessor(
      conn_, [](void*, const char*) {}, nullptr);
}

PgConnection::~PgConnection() {
  if (conn_ != nullptr) PQfinish(conn_);
}

void PgConnection::fail(std::string_view what, pg_result* result) const {
  std::string why = one_line(result != nullptr ? PQresultErrorMessage(result) : PQerrorMessage(conn_));
  if (why.empty()) why = one_line(PQerrorMessage(conn_));
  if (result != nullptr) PQclear(result);
  throw ArchiveError(name_ + ": " + why + " (" + std::string(what) + ")");
}

PgResult PgConnection::checked(pg_result* result, std::string_view what) {
  if (result == nullptr) fail(what);
  const auto status = PQresultStatus(result);
  if (status != PGRES_COMMAND_OK && status != PGRES_TUPLES_OK) fail(what, result);
  return PgResult(result);
}

void PgConnection::exec(std::string_view sql) {
  const std::string text(sql);
  checked(PQexec(conn_, text.c_str()), text.substr(0, text.find_first_of(" \n")));
}

PgResult PgConnection::query(std::string_view sql, const std::vector<std::optional<std::string>>& params) {
  const std::string text(sql);
  std::vector<const char*> values;
  for (const auto& p : params) values.push_back(p ? p->c_str() : nullptr);
  return checked(
      PQexecParams(conn_, text.c_str(), static_cast<int>(values.size()), nullptr, values.data(), nullptr, nullptr, 0),
      text.substr(0, text.find_first_of(" \n")));
}

void PgConnection::copy_in(std::string_view copy_sql, std::string_view data) {
  const std::string text(copy_sql);
  pg_result* start = PQexec(conn_, text.c_str());
  if (start == nullptr || PQresultStatus(start) != PGRES_COPY_IN) fail("starting " + text, start);
  PQclear(start);
  if (PQputCopyData(conn_, data.data(), static_cast<int>(data.size())) != 1) fail("sending rows");
  if (PQputCopyEnd(conn_, nullptr) != 1) fail("ending a COPY");
  // The COPY's own outcome (a row refused, a duplicate key), then the end of results.
  checked(PQgetResult(conn_), text);
  while (pg_result* rest = PQgetResult(conn_)) PQclear(rest);
}

void PgConnection::copy_out(std::string_view copy_sql, const std::function<void(std::string_view line)>& line) {
  const std::string text(copy_sql);
  pg_result* start = PQexec(conn_, text.c_str());
  if (start == nullptr || PQresultStatus(start) != PGRES_COPY_OUT) fail("starting " + text, start);
  PQclear(start);
  char* buffer = nullptr;
  int length = 0;
  while ((length = PQgetCopyData(conn_, &buffer, /*async=*/0)) > 0) {
    std::string_view row(buffer, static_cast<std::size_t>(length));
    if (!row.empty() && row.back() == '\n') row.remove_suffix(1);
    try {
      line(row);
    } catch (...) {
      PQfreemem(buffer);
      // Drain the rest so the connection stays usable for the caller's next statement.
      while ((length = PQgetCopyData(conn_, &buffer, 0)) > 0) PQfreemem(buffer);
      while (pg_result* rest = PQgetResult(conn_)) PQclear(rest);
      throw;
    }
    PQfreemem(buffer);
  }
  if (length == -2) fail("reading rows");
  checked(PQgetResult(conn_), text);
  while (pg_result* rest = PQgetResult(conn_)) PQclear(rest);
}

std::string PgConnection::literal(std::string_view value) const {
  char* quoted = PQescapeLiteral(conn_, value.data(), value.size());
  if (quoted == nullptr) fail("quoting a value");
  std::string text(quoted);
  PQfreemem(quoted);
  return text;
}

void PgConnection::interrupt() noexcept {
  // shutdown() wakes a thread blocked on the socket, where close() would leave it waiting (or, worse, let the number
  // be reused under it).
  if (const int socket = PQsocket(conn_); socket >= 0) ::shutdown(socket, SHUT_RDWR);
}

void PgConnection::rollback() noexcept {
  // After a failed statement the transaction is aborted: ROLLBACK ends it. A connection gone has nothing to end.
  if (PQtransactionStatus(conn_) == PQTRANS_IDLE || PQstatus(conn_) != CONNECTION_OK) return;
  PQclear(PQexec(conn_, "ROLLBACK"));
}

}  // namespace imubridge::archive
