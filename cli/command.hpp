#pragma once
// Each subcommand lives in cli/commands/<name>.cpp and registers itself with the program's parser.
// A command's run function returns the process exit code: 0 success, 1 runtime failure, 2 bad usage/config.
#include <functional>
#include <vector>

namespace CLI {
class App;
}

namespace imubridge::cli {

using CommandRunner = std::function<int()>;

struct CommandRegistration {
  // Adds the subcommand and its options to `app`, and returns what to run when it is chosen.
  std::function<CommandRunner(CLI::App& app)> add;
};

// Commands add themselves from static initialisers in their own files.
std::vector<CommandRegistration>& command_registry();
struct RegisterCommand {
  explicit RegisterCommand(std::function<CommandRunner(CLI::App&)> add) {
    command_registry().push_back({std::move(add)});
  }
};

}  // namespace imubridge::cli
