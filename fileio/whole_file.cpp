#include "fileio/whole_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <system_error>

namespace imubridge::fileio {
namespace {

[[noreturn]] void fail(const std::filesystem::path& target, const std::string& reason) {
  throw std::runtime_error("cannot write " + target.string() + ": " + reason);
}

// The mode a plain open(O_CREAT, 0666) would give a new file, or the existing target's: mkstemp makes it 0600.
mode_t mode_for(const std::filesystem::path& target) {
  struct stat existing {};
  if (::stat(target.c_str(), &existing) == 0) return existing.st_mode & 07777;
  const mode_t mask = ::umask(0);
  ::umask(mask);
  return 0666 & ~mask;
}

}  // namespace

WholeFile::WholeFile(std::filesystem::path target) : target_(std::move(target)) {
  if (std::filesystem::is_directory(target_)) fail(target_, "it is a directory");
  // Same folder, so the rename is atomic (one file system); hidden, so a half-written one is not mistaken for output.
  std::string pattern = (target_.parent_path() / ("." + target_.filename().string() + ".XXXXXX")).string();
  const int fd = ::mkstemp(pattern.data());
  if (fd < 0) fail(target_, std::strerror(errno));
  ::fchmod(fd, mode_for(target_));
  ::close(fd);
  temporary_ = pattern;
  out_.open(temporary_, std::ios::binary | std::ios::trunc);
  if (!out_) {
    std::filesystem::remove(temporary_);
    fail(target_, "cannot open " + temporary_.string());
  }
}

WholeFile::~WholeFile() {
  if (committed_) return;
  out_.close();
  std::error_code ignored;
  std::filesystem::remove(temporary_, ignored);
}

void WholeFile::commit() {
  out_.flush();
  const bool written = out_.good();
  out_.close();
  if (!written || out_.fail()) fail(target_, "write error");
  // On disk before the rename: after a power loss the target is the old file or the new one, never an empty one.
  const int fd = ::open(temporary_.c_str(), O_RDONLY);
  const bool synced = fd >= 0 && ::fsync(fd) == 0;
  const int sync_errno = errno;
  if (fd >= 0) ::close(fd);
  if (!synced) fail(target_, std::strerror(sync_errno));
  if (::rename(temporary_.c_str(), target_.c_str()) != 0) fail(target_, std::strerror(errno));
  committed_ = true;
}

void write_whole_file(const std::filesystem::path& target, std::string_view content) {
  WholeFile file(target);
  file.stream().write(content.data(), static_cast<std::streamsize>(content.size()));
  file.commit();
}

}  // namespace imubridge::fileio
