#include "tests/support/postgres_server.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <pwd.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <system_error>

namespace imubridge::test {
namespace {

// Debian's server binaries (postgresql-15); the newest installed version wins.
std::filesystem::path server_bin_dir() {
  namespace fs = std::filesystem;
  fs::path best;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator("/usr/lib/postgresql", ec)) {
    if (fs::exists(entry.path() / "bin" / "initdb") && entry.path() > best) best = entry.path();
  }
  if (best.empty()) throw std::runtime_error("no PostgreSQL server in /usr/lib/postgresql: run scripts/setup");
  return best / "bin";
}

std::string quoted(const std::string& text) {
  std::string q = "'";
  for (char c : text) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string run_capturing(const std::string& command, int& status) {
  std::string output;
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) throw std::runtime_error("cannot run " + command);
  std::array<char, 4096> buffer{};
  while (std::fgets(buffer.data(), buffer.size(), pipe) != nullptr) output += buffer.data();
  status = ::pclose(pipe);
  return output;
}

std::string slurp_file(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

}  // namespace

std::string PostgresServer::as_server_user(const std::string& command) const {
  if (::geteuid() != 0) return command;
  return "runuser -u postgres -- " + command;
}

PostgresServer::PostgresServer(PostgresServerOptions options) : bin_(server_bin_dir()) {
  std::string pattern = (std::filesystem::temp_directory_path() / "imubridge_pg_XXXXXX").string();
  if (::mkdtemp(pattern.data()) == nullptr) throw std::runtime_error("cannot create a temporary directory");
  dir_ = pattern;
  if (::geteuid() == 0) {
    const passwd* postgres = ::getpwnam("postgres");
    if (postgres == nullptr) throw std::runtime_error("we are root and there is no postgres user: run scripts/setup");
    if (::chown(dir_.c_str(), postgres->pw_uid, postgres->pw_gid) != 0) {
      throw std::runtime_error("cannot give " + dir_.string() + " to the postgres user");
    }
  }
  const auto data = dir_ / "data";
  int status = 0;
  const std::string initdb =
      run_capturing(as_server_user(quoted((bin_ / "initdb").string()) + " -D " + quoted(data.string()) +
                                   " -U postgres -A trust -E UTF8 --no-sync --no-instructions"),
                    status);
  if (status != 0) throw std::runtime_error("initdb failed: " + initdb);
  settings_ = "-c listen_addresses=127.0.0.1 -c unix_socket_directories=" + dir_.string();
  if (!options.durable) settings_ += " -c fsync=off -c synchronous_commit=off -c full_page_writes=off";
  // A port found free can be taken before the server binds it: try a few.
  std::string log;
  for (int attempt = 0; attempt < 5 && !running_; ++attempt) {
    port_ = free_loopback_port();
    log = pg_ctl_start();
  }
  if (!running_) throw std::runtime_error("PostgreSQL did not start: " + log + slurp_file(dir_ / "server.log"));
}

std::string PostgresServer::pg_ctl_start() {
  int status = 0;
  const std::string log =
      run_capturing(as_server_user(quoted((bin_ / "pg_ctl").string()) + " -D " + quoted((dir_ / "data").string()) +
                                   " -l " + quoted((dir_ / "server.log").string()) + " -w -t 30 -o " +
                                   quoted("-p " + std::to_string(port_) + " " + settings_) + " start"),
                    status);
  running_ = status == 0;
  return log;
}

void PostgresServer::start() {
  if (running_) return;
  const std::string log = pg_ctl_start();
  if (!running_) throw std::runtime_error("PostgreSQL did not start again: " + log);
}

PostgresServer::~PostgresServer() {
  stop();
  std::error_code ec;
  std::filesystem::remove_all(dir_, ec);
}

void PostgresServer::stop() {
  if (!running_) return;
  int status = 0;
  run_capturing(as_server_user(quoted((bin_ / "pg_ctl").string()) + " -D " + quoted((dir_ / "data").string()) +
                               " -m fast -w stop"),
                status);
  running_ = false;
}

std::string PostgresServer::url(const std::string& database) const {
  return "postgresql://postgres@127.0.0.1:" + std::to_string(port_) + "/" + database;
}

void PostgresServer::create_database(const std::string& name) const { psql("postgres", "CREATE DATABASE " + name); }

std::string PostgresServer::psql(const std::string& database, const std::string& sql) const {
  int status = 0;
  const std::string output = run_capturing(quoted((bin_ / "psql").string()) + " -X -q -A -t -v ON_ERROR_STOP=1 -d " +
                                               quoted(url(database)) + " -c " + quoted(sql),
                                           status);
  if (status != 0) throw std::runtime_error("psql failed: " + output);
  return output;
}

}  // namespace imubridge::test
