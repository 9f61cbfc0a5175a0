#pragma once
// The serial ports this machine has, with the USB identity of each (libserialport), and finding a configured device
// among them: a USB radio keeps its vendor, product and serial number when it re-enumerates as another /dev/ttyUSB*.
#include <cstdint>
#include <filesystem>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <string>
#include <vector>

#include "daemon/config.hpp"

namespace imubridge::daemon {

struct PortInfo {
  std::string path;         // /dev/ttyUSB0
  std::string description;  // libserialport's, e.g. "FT232R USB UART"
  std::string transport;    // "usb", "bluetooth" or "native"
  std::optional<std::uint16_t> usb_vid, usb_pid;
  std::string usb_serial, usb_manufacturer, usb_product;  // empty when the device reports none
  std::vector<std::string> by_id;  // /dev/serial/by-id links to it: names that survive re-enumeration
};

// Every port libserialport finds, sorted by path. Throws std::runtime_error if the system cannot be asked.
std::vector<PortInfo> list_ports();
void to_json(nlohmann::json& j, const PortInfo& port);

// "usb 0403:6001 serial A50285BI" or the path: how logs and the store name a configured device.
std::string describe(const DeviceSelector& device);
bool matches(const PortInfo& port, const DeviceSelector& device);

// The path to open for `device` now: its path, or the one port in `ports` with its USB identity. Throws
// std::runtime_error saying why there is none: no such port, or several (then a serial number tells them apart).
std::filesystem::path resolve(const DeviceSelector& device, const std::vector<PortInfo>& ports);

}  // namespace imubridge::daemon
