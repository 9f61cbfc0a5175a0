#pragma once
// A log file's bytes, for the readers that parse a whole file at once (ULog, tlog).
#include <cstdint>
#include <filesystem>
#include <optional>
#include <vector>

namespace imubridge::importers {

// The whole of a regular file, in one read (a byte at a time through istreambuf_iterator cost as much as parsing
// it); nullopt when `path` is not a regular file or cannot be read whole.
std::optional<std::vector<std::uint8_t>> read_file_bytes(const std::filesystem::path& path);

}  // namespace imubridge::importers
