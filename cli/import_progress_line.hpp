#pragma once
// `imubridge import`'s progress on a terminal: one line, rewritten in place (`\r`), at most about ten times a second,
// ended with a newline by finish() so the summary starts on a line of its own. Where stderr is no terminal (tests,
// systemd, pipes) it writes nothing at all.
#include <chrono>
#include <cstdio>
#include <string>
#include <string_view>

#include "importers/import_progress.hpp"

namespace imubridge::cli {

class ImportProgressLine {
 public:
  // Shown when `out` is a terminal.
  explicit ImportProgressLine(std::string file_name, std::FILE* out = stderr);
  ImportProgressLine(std::string file_name, std::FILE* out, bool shown);
  ~ImportProgressLine();
  ImportProgressLine(const ImportProgressLine&) = delete;
  ImportProgressLine& operator=(const ImportProgressLine&) = delete;

  bool shown() const { return shown_; }
  // For an importer's options: empty when the line is not shown, so the importer does no work for it.
  importers::ImportProgressCallback callback();
  void update(const importers::ImportProgress& progress);
  // Draws the last state and ends the line (once; nothing if nothing was reported).
  void finish();

  // "importing sample.ulg  42% 1.7/4.0 MB  12,345 samples" (no samples part while there are none).
  static std::string format(std::string_view file_name, const importers::ImportProgress& progress);

 private:
  void draw();

  std::string name_;
  std::FILE* out_;
  bool shown_;
  bool reported_ = false, finished_ = false;
  importers::ImportProgress last_{};
  std::chrono::steady_clock::time_point drawn_at_{};
  bool drawn_ = false;
};

}  // namespace imubridge::cli
