#pragma once
// A file a command writes for its user (an export, PARAMS.json, a report) is either the complete new content or what
// was there before: the bytes go to a temporary file in the same folder, which is renamed over the target only once
// everything was written and flushed to disk. A command that fails half-way (an unknown session found after the
// file was opened, a full disk, Ctrl-C) leaves an existing file as it was and no partial file behind.
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

namespace imubridge::fileio {

class WholeFile {
 public:
  // Creates the temporary file next to `target`. Throws std::runtime_error "cannot write TARGET: REASON".
  explicit WholeFile(std::filesystem::path target);
  WholeFile(const WholeFile&) = delete;
  WholeFile& operator=(const WholeFile&) = delete;
  // Without commit(): removes the temporary file, leaving the target untouched.
  ~WholeFile();

  std::ostream& stream() { return out_; }
  // Flushes, syncs and renames the temporary file over the target. Throws std::runtime_error on a write error.
  void commit();

  const std::filesystem::path& target() const { return target_; }

 private:
  std::filesystem::path target_, temporary_;
  std::ofstream out_;
  bool committed_ = false;
};

// `content` as the whole of `target`, through a WholeFile.
void write_whole_file(const std::filesystem::path& target, std::string_view content);

}  // namespace imubridge::fileio
