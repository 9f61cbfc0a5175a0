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
enum class ExportFormat { csv, jsonl };

// Throw std::invalid_argument naming the valid choices.
ExportTable parse_export_table(std::string_view name);
ExportFormat parse_export_format(std::string_view name);

// `run` picks the estimates' run; it may be left out when the session has exactly one. Throws std::invalid_argument
// for an unknown session or run, or a run given for another table.
void export_table(const store::Store& store, std::int64_t session, ExportTable table, std::optional<std::int64_t> run,
                  ExportFormat format, std::ostream& out);

}  // namespace imubridge::replay
