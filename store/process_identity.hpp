#pragma once
// Who writes a session: enough to tell later, from another process, whether that writer still runs. A pid alone is
// not: after a reboot or once the pid is reused it names another process. The boot id (random at every boot) and the
// process's start time (clock ticks since boot, which no two processes holding the same pid in one boot share) make
// it unique. Every writer of a store runs on the same host (SQLite's WAL needs shared memory, so never a network
// file system), so a boot id other than ours means the writer's machine has rebooted since: it is gone.
#include <cstdint>
#include <optional>
#include <string>

namespace imubridge::store {

struct ProcessIdentity {
  std::int64_t pid = 0;
  std::string boot_id{};         // /proc/sys/kernel/random/boot_id
  std::int64_t start_ticks = 0;  // field 22 of /proc/<pid>/stat
  friend bool operator==(const ProcessIdentity&, const ProcessIdentity&) = default;
};

// This process's identity; nothing where /proc does not tell it (then its sessions are never taken for dead).
std::optional<ProcessIdentity> this_process();
// Whether the process `writer` names still runs: false once its machine rebooted, its pid is gone or now names a
// process started at another time. A pid in use by a process /proc hides from us (hidepid) counts as running.
bool is_running(const ProcessIdentity& writer);

}  // namespace imubridge::store
