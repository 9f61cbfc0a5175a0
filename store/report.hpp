#pragma once
// Where the store says what it cannot throw: a failed checkpoint on its background thread (wal_checkpointer.hpp), a
// commit failing in a destructor. The store does not log (it has no logger to depend on); a program that does routes
// these lines into its log with set_report_sink(). Without a sink they go to stderr.
#include <functional>
#include <string_view>

namespace imubridge::store {

// Gets one line without a newline, naming the database file. Called from whichever thread failed.
using ReportSink = std::function<void(std::string_view line)>;

// For every store of the process; an empty sink restores stderr. Safe to call while stores run.
void set_report_sink(ReportSink sink);
void report(std::string_view line);

}  // namespace imubridge::store
