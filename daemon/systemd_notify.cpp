#include "daemon/systemd_notify.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#ifdef IMUBRIDGE_HAVE_SYSTEMD
#include <systemd/sd-daemon.h>
#endif

namespace imubridge::daemon {

SystemdNotifier::SystemdNotifier() {
#ifdef IMUBRIDGE_HAVE_SYSTEMD
  std::uint64_t usec = 0;
  if (sd_watchdog_enabled(0, &usec) > 0 && usec > 0) watchdog_period_ = std::chrono::microseconds(usec / 2);
#endif
}

void SystemdNotifier::notify(const std::string& state) {
#ifdef IMUBRIDGE_HAVE_SYSTEMD
  sd_notify(0, state.c_str());
#else
  (void)state;
#endif
}

void SystemdNotifier::ready(std::string_view status) { notify("READY=1\nSTATUS=" + std::string(status)); }
void SystemdNotifier::status(std::string_view status) { notify("STATUS=" + std::string(status)); }
void SystemdNotifier::watchdog() { notify("WATCHDOG=1"); }
void SystemdNotifier::stopping() { notify("STOPPING=1\nSTATUS=stopping"); }

bool stderr_is_journal() {
  const char* stream = std::getenv("JOURNAL_STREAM");
  struct stat st {};
  if (!stream || ::fstat(STDERR_FILENO, &st) != 0) return false;
  unsigned long long device = 0, inode = 0;
  if (std::sscanf(stream, "%llu:%llu", &device, &inode) != 2) return false;
  return device == st.st_dev && inode == st.st_ino;
}

}  // namespace imubridge::daemon
