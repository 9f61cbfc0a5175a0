// Finding a configured device among the serial ports: by path, or by the USB identity that survives re-enumeration.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "daemon/port_list.hpp"

namespace imubridge::daemon {
namespace {

PortInfo usb_port(std::string path, std::uint16_t vid, std::uint16_t pid, std::string serial) {
  PortInfo p;
  p.path = std::move(path);
  p.transport = "usb";
  p.usb_vid = vid;
  p.usb_pid = pid;
  p.usb_serial = std::move(serial);
  return p;
}

DeviceSelector usb(std::uint16_t vid, std::uint16_t pid, std::optional<std::string> serial = std::nullopt) {
  DeviceSelector d;
  d.usb_vid = vid;
  d.usb_pid = pid;
  d.usb_serial = std::move(serial);
  return d;
}

// Two identical FTDI radios and a flight controller, as a ground station might have them.
const std::vector<PortInfo> kPorts{usb_port("/dev/ttyACM0", 0x1209, 0x5741, "FC01"),
                                   usb_port("/dev/ttyUSB0", 0x0403, 0x6015, "DN02ABCD"),
                                   usb_port("/dev/ttyUSB1", 0x0403, 0x6015, "DN02WXYZ")};

TEST(PortList, AUsbIdentityFindsItsPortWhereverItEnumerated) {
  EXPECT_EQ(resolve(usb(0x0403, 0x6015, "DN02WXYZ"), kPorts), "/dev/ttyUSB1");
  std::vector<PortInfo> replugged = kPorts;
  replugged[2].path = "/dev/ttyUSB4";
  EXPECT_EQ(resolve(usb(0x0403, 0x6015, "DN02WXYZ"), replugged), "/dev/ttyUSB4");
  EXPECT_EQ(resolve(usb(0x1209, 0x5741), kPorts), "/dev/ttyACM0") << "one port of that kind needs no serial";
}

TEST(PortList, NoMatchAndSeveralMatchesAreExplained) {
  try {
    resolve(usb(0x0403, 0x6015), kPorts);
    FAIL() << "two radios match";
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(),
                 "2 ports are usb 0403:6015: /dev/ttyUSB0 (serial DN02ABCD), /dev/ttyUSB1 (serial DN02WXYZ); give the "
                 "serial number to choose one");
  }
  try {
    resolve(usb(0x0403, 0x6015, "NOPE"), kPorts);
    FAIL() << "no radio has that serial";
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "no serial port is usb 0403:6015 serial NOPE");
  }
}

TEST(PortList, APathIsTakenAsItIs) {
  DeviceSelector d;
  d.path = "/tmp/pty-link";
  EXPECT_EQ(resolve(d, {}), "/tmp/pty-link") << "ptys and symlinks are not in the port list, and need not be";
  EXPECT_EQ(describe(d), "/tmp/pty-link");
  EXPECT_TRUE(matches(kPorts[1], [] {
    DeviceSelector p;
    p.path = "/dev/ttyUSB0";
    return p;
  }()));
}

TEST(PortList, JsonShowsTheUsbIdentityInHex) {
  const nlohmann::json j = kPorts[1];
  EXPECT_EQ(j.at("path"), "/dev/ttyUSB0");
  EXPECT_EQ(j.at("usb").at("vid"), "0403");
  EXPECT_EQ(j.at("usb").at("pid"), "6015");
  EXPECT_EQ(j.at("usb").at("serial"), "DN02ABCD");
  PortInfo native;
  native.path = "/dev/ttyS0";
  native.transport = "native";
  EXPECT_FALSE(nlohmann::json(native).contains("usb"));
}

}  // namespace
}  // namespace imubridge::daemon
