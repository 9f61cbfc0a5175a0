// imubridge: a ground-station daemon for quadrotor IMU streams. See README.md and docs/.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>
#include <map>
#include <stdexcept>
#include <string>
#include <string_view>

#include "cli/command.hpp"
#include "identification/solver_logs.hpp"
#include "store/report.hpp"

namespace imubridge::cli {
std::vector<CommandRegistration>& command_registry() {
  static std::vector<CommandRegistration> registry;
  return registry;
}
}  // namespace imubridge::cli

int main(int argc, char** argv) {
  using namespace imubridge::cli;
  imubridge::estimator::route_solver_logs_to_spdlog();
  // The store's background failures (a checkpoint on a full disk) belong in the daemon's log, with everything else.
  imubridge::store::set_report_sink([](std::string_view line) { spdlog::error("store: {}", line); });
  CLI::App app{"imubridge " IMUBRIDGE_VERSION
               " - records quadrotor IMU serial streams into SQLite and estimates velocity from them"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string(IMUBRIDGE_VERSION));
  std::map<CLI::App*, CommandRunner> runners;
  for (auto& registration : command_registry()) {
    CommandRunner runner = registration.add(app);
    runners[app.get_subcommands({}).back()] = std::move(runner);  // the subcommand add() just created
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::Success& e) {  // --help, --version
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);  // one line naming the bad option, and a pointer to --help
    return 2;
  }
  for (auto* sub : app.get_subcommands()) {
    try {
      return runners.at(sub)();
    } catch (const std::invalid_argument& e) {  // bad input the user can fix: a value, a config key, a name
      std::fprintf(stderr, "imubridge %s: error: %s\n", sub->get_name().c_str(), e.what());
      return 2;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "imubridge %s: error: %s\n", sub->get_name().c_str(), e.what());
      return 1;
    }
  }
  return 2;
}
