#include "store/process_identity.hpp"

#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <fstream>
#include <sstream>

namespace imubridge::store {
namespace {

std::string current_boot_id() {
  std::ifstream in("/proc/sys/kernel/random/boot_id");
  std::string id;
  std::getline(in, id);
  return id;
}

struct ProcStat {
  char state = '?';
  std::int64_t start_ticks = 0;
};

// Fields 3 and 22 of /proc/<pid>/stat. The command name (field 2) may hold spaces and parentheses: fields are
// counted from its closing parenthesis, the last one on the line.
std::optional<ProcStat> proc_stat(std::int64_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(in, line)) return std::nullopt;
  const auto name_end = line.rfind(')');
  if (name_end == std::string::npos) return std::nullopt;
  std::istringstream fields(line.substr(name_end + 1));
  ProcStat stat;
  std::string field;
  fields >> stat.state;
  for (int n = 4; n < 22; ++n) fields >> field;  // ppid (4) ... itrealvalue (21)
  if (!(fields >> stat.start_ticks)) return std::nullopt;
  return stat;
}

}  // namespace

std::optional<ProcessIdentity> this_process() {
  const std::int64_t pid = ::getpid();
  const std::string boot_id = current_boot_id();
  const auto stat = proc_stat(pid);
  if (boot_id.empty() || !stat) return std::nullopt;
  return ProcessIdentity{.pid = pid, .boot_id = boot_id, .start_ticks = stat->start_ticks};
}

bool is_running(const ProcessIdentity& writer) {
  const std::string boot_id = current_boot_id();
  if (boot_id.empty()) return true;  // no /proc to ask: never take a writer for dead on no evidence
  if (writer.boot_id != boot_id) return false;
  const auto stat = proc_stat(writer.pid);
  if (!stat) {
    // Another user's process is invisible in /proc under hidepid (the unit's ProtectProc=invisible), but a signal 0
    // still tells a pid that is in use (EPERM) from one that is not: in use, whether it is the writer cannot be told.
    return ::kill(static_cast<pid_t>(writer.pid), 0) == 0 || errno == EPERM;
  }
  // A zombie (Z, or X while it is reaped) has ended; only its parent has not collected its status yet.
  return stat->start_ticks == writer.start_ticks && stat->state != 'Z' && stat->state != 'X';
}

}  // namespace imubridge::store
