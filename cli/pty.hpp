#pragma once
// A pseudo-terminal pair standing in for a serial device: programs open the slave side (through a symlink at a
// path of our choosing, as `socat` makes) and we write into the master side.
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>

namespace imubridge::cli {

class PtyPair {
 public:
  // Opens a pair in raw mode and points `link_path` at the slave (replacing an old symlink there, never a file).
  explicit PtyPair(std::filesystem::path link_path);
  // Closes both sides and removes the symlink. Closing hangs the slave up: whatever its reader has not read yet is
  // discarded, so call drain() first when the tail matters.
  ~PtyPair();
  PtyPair(const PtyPair&) = delete;
  PtyPair& operator=(const PtyPair&) = delete;

  // Like a UART with nobody listening, bytes that do not fit the pty's buffer are dropped, and counted. A reader
  // that keeps up gets a moment to make room; once bytes were dropped, none is waited for until it makes room.
  void write(std::span<const std::uint8_t> bytes);
  // Waits until the slave's reader has read every byte written, or has read nothing for `patience`. Returns 0 when
  // it read them all, else the bytes left in the slave's input queue (a lower bound: the pty buffers more).
  std::size_t drain(std::chrono::milliseconds patience = std::chrono::milliseconds(500));

  const std::string& slave_name() const { return slave_name_; }
  std::uint64_t dropped_bytes() const { return dropped_; }
  int master_fd() const { return master_; }

 private:
  std::filesystem::path link_path_;
  std::string slave_name_;
  int master_ = -1;
  int slave_ = -1;  // held open so the pair survives readers coming and going, and to look at its input queue
  std::uint64_t dropped_ = 0;
  bool reader_behind_ = false;  // the last write dropped bytes: do not wait for room again until there is some
};

}  // namespace imubridge::cli
