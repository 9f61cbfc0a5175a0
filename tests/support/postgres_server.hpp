#pragma once
// A real PostgreSQL server for tests and benchmarks: initdb in a fresh temporary directory, started on a free
// loopback port (and a socket in that directory), stopped and removed at the end. Run as the postgres user when we
// are root (the server refuses to run as root), as ourselves otherwise. scripts/setup installs the server.
#include <cstdint>
#include <filesystem>
#include <string>

#include "tests/support/loopback_port.hpp"

namespace imubridge::test {

struct PostgresServerOptions {
  // Tests lose nothing by skipping the disk (the server's crash safety is not what they check); a benchmark that
  // measures what a station would get keeps it.
  bool durable = false;
};

class PostgresServer {
 public:
  // Starts the server or throws std::runtime_error with the reason and the server's log.
  explicit PostgresServer(PostgresServerOptions options = {});
  ~PostgresServer();
  PostgresServer(const PostgresServer&) = delete;
  PostgresServer& operator=(const PostgresServer&) = delete;

  std::uint16_t port() const { return port_; }
  // postgresql://postgres@127.0.0.1:PORT/DATABASE
  std::string url(const std::string& database = "postgres") const;
  // Creates a database (each test its own, on one server).
  void create_database(const std::string& name) const;
  // Runs SQL through psql and returns its unaligned, tuples-only output (fields separated by '|').
  std::string psql(const std::string& database, const std::string& sql) const;
  // Stops the server (fast shutdown), and starts it again on the same port and data: an archive going away and
  // coming back. The destructor stops it if it runs.
  void stop();
  void start();

 private:
  std::string as_server_user(const std::string& command) const;
  std::string pg_ctl_start();  // pg_ctl's output; sets running_
  std::filesystem::path dir_;
  std::filesystem::path bin_;
  std::string settings_;
  std::uint16_t port_ = 0;
  bool running_ = false;
};

}  // namespace imubridge::test
