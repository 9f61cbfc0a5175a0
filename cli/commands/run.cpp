// `imubridge run`: the ground-station daemon (daemon/daemon.hpp). The configuration file and how the command line
// overrides it: docs/config.md; signals, systemd and storage limits: docs/operations.md.
#include <CLI/CLI.hpp>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "cli/command.hpp"
#include "daemon/config_file.hpp"
#include "daemon/daemon.hpp"
#include "daemon/link_spec.hpp"

namespace imubridge::cli {
namespace {

namespace fs = std::filesystem;

struct RunOptions {
  std::string config_file, db, params, log_level;
  std::vector<std::string> links;
};

const RegisterCommand kRun([](CLI::App& app) -> CommandRunner {
  auto o = std::make_shared<RunOptions>();
  auto* cmd = app.add_subcommand("run", "Record IMU serial links into SQLite, estimate velocity live and publish it");
  cmd->add_option(
      "--config", o->config_file,
      "TOML configuration (docs/config.md); default " + daemon::kDefaultConfigPath.string() + " when it exists");
  cmd->add_option("--db", o->db, "Record into this database (overrides store.path)");
  cmd->add_option("--link", o->links,
                  "NAME=DEVICE:PROTOCOL[:BAUD], repeatable; DEVICE is a path or usb:VID:PID[:SERIAL]. Replaces the "
                  "device, protocol and baud of the file's link NAME, or adds a link");
  cmd->add_option("--params", o->params, "PARAMS.json from `imubridge identify` (overrides params)");
  cmd->add_option("--log-level", o->log_level, "Overrides log_level")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error"}));
  return [o] {
    // An explicitly named file must exist; the default one may be absent when the command line names the links.
    std::optional<fs::path> file;
    if (!o->config_file.empty()) {
      file = o->config_file;
    } else if (std::error_code ec; fs::exists(daemon::kDefaultConfigPath, ec)) {
      file = daemon::kDefaultConfigPath;
    }
    daemon::Config config = file ? daemon::load_config(*file) : daemon::Config{};
    for (const auto& spec : o->links) daemon::apply_link_spec(config, daemon::parse_link_spec(spec));
    if (!o->db.empty()) config.store.path = o->db;
    if (!o->params.empty()) config.params = o->params;
    if (!o->log_level.empty()) config.log_level = o->log_level;
    daemon::validate(config, file ? file->string() : "");
    daemon::configure_logging(config);
    daemon::Daemon daemon(std::move(config), file);
    return daemon.run();
  };
});

}  // namespace
}  // namespace imubridge::cli
