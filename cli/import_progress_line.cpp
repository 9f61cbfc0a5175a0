#include "cli/import_progress_line.hpp"

#include <unistd.h>

#include <algorithm>
#include <cinttypes>
#include <filesystem>
#include <utility>

namespace imubridge::cli {
namespace {

constexpr auto kRedrawEvery = std::chrono::milliseconds(100);

std::string with_commas(std::uint64_t n) {
  std::string digits = std::to_string(n), out;
  for (std::size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) out += ',';
    out += digits[i];
  }
  return out;
}

}  // namespace

ImportProgressLine::ImportProgressLine(std::string file_name, std::FILE* out)
    : ImportProgressLine(std::move(file_name), out, ::isatty(::fileno(out)) == 1) {}

ImportProgressLine::ImportProgressLine(std::string file_name, std::FILE* out, bool shown)
    : name_(std::filesystem::path(file_name).filename().string()), out_(out), shown_(shown) {
  if (name_.empty()) name_ = std::move(file_name);
}

ImportProgressLine::~ImportProgressLine() { finish(); }

importers::ImportProgressCallback ImportProgressLine::callback() {
  if (!shown_) return {};
  return [this](const importers::ImportProgress& p) { update(p); };
}

void ImportProgressLine::update(const importers::ImportProgress& progress) {
  if (!shown_ || finished_) return;
  last_ = progress;
  reported_ = true;
  const auto now = std::chrono::steady_clock::now();
  if (drawn_ && now - drawn_at_ < kRedrawEvery) return;
  drawn_at_ = now;
  draw();
}

void ImportProgressLine::finish() {
  if (!shown_ || finished_ || !reported_) return;
  finished_ = true;
  draw();
  std::fputc('\n', out_);
  std::fflush(out_);
}

void ImportProgressLine::draw() {
  drawn_ = true;
  std::fprintf(out_, "\r\033[K%s", format(name_, last_).c_str());
  std::fflush(out_);
}

std::string ImportProgressLine::format(std::string_view file_name, const importers::ImportProgress& p) {
  const std::uint64_t total = p.bytes_total, read = std::min(p.bytes_read, p.bytes_total);
  const int percent = total == 0 ? 100 : static_cast<int>(read * 100 / total);
  const bool mb = total >= 1'000'000;
  const double unit = mb ? 1e6 : 1e3;
  char text[96];
  std::snprintf(text, sizeof text, " %3d%% %.1f/%.1f %s", percent, static_cast<double>(read) / unit,
                static_cast<double>(total) / unit, mb ? "MB" : "kB");
  std::string line = "importing " + std::string(file_name) + text;
  if (p.samples > 0) line += "  " + with_commas(p.samples) + (p.samples == 1 ? " sample" : " samples");
  return line;
}

}  // namespace imubridge::cli
