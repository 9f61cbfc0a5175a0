#include "daemon/port_list.hpp"

#include <libserialport.h>

#include <algorithm>
#include <memory>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <system_error>

#include "protocol/hex.hpp"

namespace imubridge::daemon {
namespace {

std::string text(const char* s) { return s ? s : ""; }

std::string usb_id(std::uint16_t vid, std::uint16_t pid) { return protocol::hex(vid, 2) + ":" + protocol::hex(pid, 2); }

// udev's stable names, when udev runs: /dev/serial/by-id/usb-FTDI_FT232R_USB_UART_A50285BI-if00-port0 -> ../../ttyUSB0
std::vector<std::string> by_id_links(const std::string& path) {
  std::vector<std::string> links;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator("/dev/serial/by-id", ec)) {
    if (std::filesystem::canonical(entry.path(), ec) == path) links.push_back(entry.path().string());
  }
  std::sort(links.begin(), links.end());
  return links;
}

}  // namespace

std::vector<PortInfo> list_ports() {
  sp_port** raw = nullptr;
  if (sp_list_ports(&raw) != SP_OK) {
    char* message = sp_last_error_message();
    const std::string why = text(message);
    sp_free_error_message(message);
    throw std::runtime_error("cannot list serial ports: " + why);
  }
  const std::unique_ptr<sp_port*, void (*)(sp_port**)> list(raw, sp_free_port_list);
  std::vector<PortInfo> ports;
  for (sp_port** p = raw; *p; ++p) {
    PortInfo info;
    info.path = text(sp_get_port_name(*p));
    info.description = text(sp_get_port_description(*p));
    switch (sp_get_port_transport(*p)) {
      case SP_TRANSPORT_USB:
        info.transport = "usb";
        break;
      case SP_TRANSPORT_BLUETOOTH:
        info.transport = "bluetooth";
        break;
      default:
        info.transport = "native";
        break;
    }
    int vid = 0, pid = 0;
    if (info.transport == "usb" && sp_get_port_usb_vid_pid(*p, &vid, &pid) == SP_OK) {
      info.usb_vid = static_cast<std::uint16_t>(vid);
      info.usb_pid = static_cast<std::uint16_t>(pid);
      info.usb_serial = text(sp_get_port_usb_serial(*p));
      info.usb_manufacturer = text(sp_get_port_usb_manufacturer(*p));
      info.usb_product = text(sp_get_port_usb_product(*p));
    }
    info.by_id = by_id_links(info.path);
    ports.push_back(std::move(info));
  }
  std::sort(ports.begin(), ports.end(), [](const PortInfo& a, const PortInfo& b) { return a.path < b.path; });
  return ports;
}

void to_json(nlohmann::json& j, const PortInfo& port) {
  j = {{"path", port.path}, {"description", port.description}, {"transport", port.transport}, {"by_id", port.by_id}};
  if (port.usb_vid) {
    j["usb"] = {{"vid", protocol::hex(*port.usb_vid, 2)},
                {"pid", protocol::hex(*port.usb_pid, 2)},
                {"serial", port.usb_serial},
                {"manufacturer", port.usb_manufacturer},
                {"product", port.usb_product}};
  }
}

std::string describe(const DeviceSelector& device) {
  if (!device.usb_vid) return device.path.string();
  std::string d = "usb " + usb_id(*device.usb_vid, *device.usb_pid);
  if (device.usb_serial) d += " serial " + *device.usb_serial;
  return d;
}

bool matches(const PortInfo& port, const DeviceSelector& device) {
  if (!device.usb_vid) return port.path == device.path;
  return port.usb_vid == device.usb_vid && port.usb_pid == device.usb_pid &&
         (!device.usb_serial || port.usb_serial == *device.usb_serial);
}

std::filesystem::path resolve(const DeviceSelector& device, const std::vector<PortInfo>& ports) {
  if (!device.usb_vid) return device.path;
  std::vector<const PortInfo*> found;
  for (const auto& port : ports) {
    if (matches(port, device)) found.push_back(&port);
  }
  if (found.empty()) throw std::runtime_error("no serial port is " + describe(device));
  if (found.size() > 1) {
    std::string which;
    for (const auto* port : found) {
      which += (which.empty() ? "" : ", ") + port->path + " (serial " +
               (port->usb_serial.empty() ? "none" : port->usb_serial) + ")";
    }
    throw std::runtime_error(std::to_string(found.size()) + " ports are " + describe(device) + ": " + which +
                             "; give the serial number to choose one");
  }
  return found.front()->path;
}

}  // namespace imubridge::daemon
