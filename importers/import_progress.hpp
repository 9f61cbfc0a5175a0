#pragma once
// How far an import has read its file, for a progress display (`imubridge import` on a terminal). The importers call
// the callback every kImportProgressEvery records or rows from their read loops, and once at the end with
// bytes_read == bytes_total; an empty callback costs one branch per batch.
#include <cstddef>
#include <cstdint>
#include <functional>

namespace imubridge::importers {

struct ImportProgress {
  std::uint64_t bytes_read = 0;   // of the file being imported, never decreasing between calls
  std::uint64_t bytes_total = 0;  // the file's size
  std::uint64_t samples = 0;      // IMU samples recorded so far (0 while a file is only being parsed)
};

using ImportProgressCallback = std::function<void(const ImportProgress&)>;

inline constexpr std::size_t kImportProgressEvery = 4096;

}  // namespace imubridge::importers
