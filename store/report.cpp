#include "store/report.hpp"

#include <cstdio>
#include <mutex>
#include <utility>

namespace imubridge::store {
namespace {

std::mutex& sink_mutex() {
  static std::mutex mutex;
  return mutex;
}

ReportSink& sink() {
  static ReportSink current;
  return current;
}

}  // namespace

void set_report_sink(ReportSink new_sink) {
  const std::lock_guard lock(sink_mutex());
  sink() = std::move(new_sink);
}

void report(std::string_view line) {
  const std::lock_guard lock(sink_mutex());  // one line at a time, and never to a sink being replaced
  if (sink()) {
    sink()(line);
  } else {
    std::fprintf(stderr, "imubridge store: %.*s\n", static_cast<int>(line.size()), line.data());
  }
}

}  // namespace imubridge::store
