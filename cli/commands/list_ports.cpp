// `imubridge list-ports`: the serial ports of this machine with their USB identities, to write a link's device
// (a path, or usb = { vid, pid, serial } that finds the same radio after it re-enumerates).
#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>

#include "cli/command.hpp"
#include "daemon/port_list.hpp"
#include "protocol/hex.hpp"

namespace imubridge::cli {
namespace {

const RegisterCommand kListPorts([](CLI::App& app) -> CommandRunner {
  auto json = std::make_shared<bool>(false);
  auto* cmd = app.add_subcommand("list-ports", "List serial ports with their USB vendor, product and serial number");
  cmd->add_flag("--json", *json, "One JSON array instead of text");
  return [json] {
    const auto ports = daemon::list_ports();
    if (*json) {
      std::printf("%s\n", nlohmann::json(ports).dump(2).c_str());
      return 0;
    }
    if (ports.empty()) std::fprintf(stderr, "no serial ports found\n");
    for (const auto& port : ports) {
      std::printf("%s  %s (%s)\n", port.path.c_str(), port.description.c_str(), port.transport.c_str());
      if (port.usb_vid) {
        std::printf("    usb = { vid = 0x%s, pid = 0x%s%s%s }  # %s %s\n", protocol::hex(*port.usb_vid, 2).c_str(),
                    protocol::hex(*port.usb_pid, 2).c_str(), port.usb_serial.empty() ? "" : ", serial = \"",
                    port.usb_serial.empty() ? "" : (port.usb_serial + "\"").c_str(), port.usb_manufacturer.c_str(),
                    port.usb_product.c_str());
      }
      for (const auto& link : port.by_id) std::printf("    %s\n", link.c_str());
    }
    return 0;
  };
});

}  // namespace
}  // namespace imubridge::cli
