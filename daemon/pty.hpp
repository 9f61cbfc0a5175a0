#pragma once
// A pseudo-terminal pair standing in for a serial device: programs open the slave side (through a symlink at a
// path of our choosing, as `socat` makes) and we write into the master side.
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>

namespace imubridge::cli {

class PtyPair {
 public:
  // Opens a pair in raw mode and points `link_path` at the slave (replacing an old symlink there, never a file).
  explicit PtyPair(std::filesystem::path link_path);
  ~PtyPair();  // closes both sides and removes the symlink
  PtyPair(const PtyPair&) = delete;
  PtyPair& operator=(const PtyPair&) = delete;

  // Like a UART with nobody listening, bytes that do not fit the pty's buffer are dropped, and counted.
  void write(std::span<const std::uint8_t> bytes);
  const std::string& slave_name() const { return slave_name_; }
  std::uint64_t dropped_bytes() const { return dropped_; }
  int master_fd() const { return master_; }

 private:
  std::filesystem::path link_path_;
  std::string slave_name_;
  int master_ = -1;
  int slave_ = -1;  // held open so the pair survives readers coming and going
  std::uint64_t dropped_ = 0;
};

}  // namespace imubridge::cli
