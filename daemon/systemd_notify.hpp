#pragma once
// The daemon's side of a Type=notify unit: READY=1, STATUS=, WATCHDOG=1 and STOPPING=1 through sd_notify. Outside
// systemd (no NOTIFY_SOCKET) and in builds without libsystemd every call does nothing.
#include <chrono>
#include <optional>
#include <string_view>

namespace imubridge::daemon {

class SystemdNotifier {
 public:
  SystemdNotifier();

  void ready(std::string_view status);
  void status(std::string_view status);
  void watchdog();
  void stopping();
  // How often to call watchdog(): half the unit's WatchdogSec, or nothing when the unit has no watchdog.
  std::optional<std::chrono::microseconds> watchdog_period() const { return watchdog_period_; }

 private:
  void notify(const std::string& state);
  std::optional<std::chrono::microseconds> watchdog_period_;
};

// Whether stderr is connected to the journal (systemd sets JOURNAL_STREAM to its device and inode): log lines then
// carry no timestamp of their own and start with a syslog priority, "<4>", which journald turns into the level.
bool stderr_is_journal();

}  // namespace imubridge::daemon
