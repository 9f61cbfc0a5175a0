#pragma once
// The npm packages tests read imubridge's output back with: each format's or protocol's own reader or client, run by
// node on a script in tests/. Installed under the build directory (IMUBRIDGE_NPM_DIR) at first use, never committed;
// node and npm are part of the machine (scripts/setup): without them a test fails, it does not skip.
#include <array>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <string_view>

namespace imubridge::test {

// Pinned: the same test reads the same way on every machine. One list and one install for every test: npm removes
// from node_modules what an install into the same folder does not name.
inline constexpr std::array<std::string_view, 3> kNpmPackages{
    "@mcap/core@2.2.2",             // cli_mcap_test
    "@foxglove/ws-protocol@0.8.0",  // cli_foxglove_test, with
    "ws@8.18.3",                    // the WebSocket it runs on under node
};

// Installs kNpmPackages unless they are there; flock, for ctest runs tests in parallel. Returns what failed, or "".
inline std::string install_npm_packages() {
  namespace fs = std::filesystem;
  const fs::path dir = IMUBRIDGE_NPM_DIR;
  const auto installed = [&] {
    for (const std::string_view package : kNpmPackages) {
      const std::string_view name = package.substr(0, package.rfind('@'));
      if (!fs::exists(dir / "node_modules" / name / "package.json")) return false;
    }
    return true;
  };
  if (installed()) return {};
  fs::create_directories(dir);
  if (std::system("command -v node >/dev/null && command -v npm >/dev/null") != 0) {
    return "node and npm are needed to run the npm packages tests read with (scripts/setup installs them)";
  }
  std::string command = "flock " + (dir / ".install.lock").string() +
                        " npm install --no-save --no-audit --no-fund --loglevel=error --prefix " + dir.string();
  for (const std::string_view package : kNpmPackages) (command += ' ') += package;
  command += " >" + (dir / "install.log").string() + " 2>&1";
  if (std::system(command.c_str()) != 0 || !installed()) {
    return "npm install failed: see " + (dir / "install.log").string();
  }
  return {};
}

// `NODE_PATH=...`: what a node script needs in its environment to find them.
inline std::string npm_node_path() { return (std::filesystem::path(IMUBRIDGE_NPM_DIR) / "node_modules").string(); }

}  // namespace imubridge::test
