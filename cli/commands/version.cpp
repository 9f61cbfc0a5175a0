// `imubridge version`: the software version, as sessions record it.
#include <CLI/CLI.hpp>
#include <cstdio>

#include "cli/command.hpp"

namespace imubridge::cli {
namespace {
const RegisterCommand kVersion([](CLI::App& app) -> CommandRunner {
  app.add_subcommand("version", "Print the imubridge version");
  return [] {
    std::printf("imubridge %s\n", IMUBRIDGE_VERSION);
    return 0;
  };
});
}  // namespace
}  // namespace imubridge::cli
