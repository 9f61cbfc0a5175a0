#include "identification/solver_logs.hpp"

#include <glog/logging.h>
#include <spdlog/spdlog.h>

#include <mutex>
#include <string_view>

namespace imubridge::estimator {
namespace {

class SpdlogSink final : public google::LogSink {
 public:
  void send(google::LogSeverity severity, const char*, const char* base_filename, int line, const struct ::tm*,
            const char* message, std::size_t message_len) override {
    // Fatal is Ceres' own bug and aborts: it is the one that deserves an error line.
    const auto level = severity >= google::GLOG_FATAL ? spdlog::level::err : spdlog::level::debug;
    spdlog::log(level, "ceres ({}:{}): {}", base_filename, line, std::string_view(message, message_len));
  }
};

}  // namespace

void route_solver_logs_to_spdlog() {
  static std::once_flag once;
  std::call_once(once, [] {
    static SpdlogSink sink;
    if (!google::IsGoogleLoggingInitialized()) google::InitGoogleLogging("imubridge");
    FLAGS_logtostderr = false;
    FLAGS_alsologtostderr = false;
    FLAGS_stderrthreshold = google::GLOG_FATAL + 1;  // nothing raw to stderr
    FLAGS_minloglevel = google::GLOG_INFO;           // but every message reaches the sink
    for (int severity = google::GLOG_INFO; severity <= google::GLOG_FATAL; ++severity)
      google::SetLogDestination(severity, "");  // an empty name: no log files
    google::AddLogSink(&sink);
  });
}

}  // namespace imubridge::estimator
