#pragma once
// A session's rows as text for notebooks, PlotJuggler and other tools: CSV with a header row, or JSON Lines (one
// object per row). Columns are the store's own (docs/storage.md); an absent value or NaN is an empty CSV field or a
// JSON null. Numbers are written with the fewest digits that read back to the same double.
#include <cstdint>
#include <optional>
#include <ostream>
#include <string_view>

#include "store/store.hpp"

namespace imubridge::replay {

enum class ExportTable { samples, estimates, reference, events };
enum class ExportFormat { csv, jsonl, mcap };
// session: one column session_t_s, seconds since the first sample, the time every other command speaks (windows of
// identify and diagnose, import's airborne span): samples and estimates count on the IMU's clock from their link's
// first sample, reference rows and events on the session's monotonic clock from the first sample's arrival.
// recorded: the store's clocks as they are, each column named by its clock (device_time_us, recv_mono_ns,
// device_t_s, mono_ns, wall_ns).
enum class ExportTime { session, recorded };

// Throw std::invalid_argument naming the valid choices.
ExportTable parse_export_table(std::string_view name);
ExportFormat parse_export_format(std::string_view name);
ExportTime parse_export_time(std::string_view name);
// "session time (s since the first sample)", for the line that says which clock an export is on.
const char* describe_export_time(ExportTime time);

// `run` picks the estimates' run; it may be left out when the session has exactly one. Throws std::invalid_argument
// for an unknown session or run, a run given for another table, or session time asked of a session without samples.
void export_table(const store::Store& store, std::int64_t session, ExportTable table, std::optional<std::int64_t> run,
                  ExportFormat format, ExportTime time, std::ostream& out);

// What export_mcap wrote.
struct McapCounts {
  std::uint64_t samples = 0, estimates = 0, reference = 0, events = 0;
};
// The whole session as MCAP (docs/replay.md): per link, /LINK/imu (samples) and /LINK/estimate (the run's
// estimates: `run`, or the session's only run; none without runs); /reference/pose (foxglove.PoseInFrame) and
// /reference/velocity; /events (foxglove.Log). JSON messages with JSON schemas. Each message's log time is on the
// session's monotonic clock in ns (samples and estimates placed on it through their link's first sample); every
// message also carries session_t_s and the store's own times. Throws as export_table does.
McapCounts export_mcap(const store::Store& store, std::int64_t session, std::optional<std::int64_t> run,
                       std::ostream& out);

}  // namespace imubridge::replay
