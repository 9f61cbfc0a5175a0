#pragma once
// Levenshtein distance (one edit: an insertion, a deletion or a substitution), for "did you mean" in the messages
// about a mistyped key: PARAMS.json's (estimator/params.cpp) and the daemon's configuration's.
#include <algorithm>
#include <cstddef>
#include <string_view>
#include <vector>

namespace imubridge::estimator {

inline std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t substitution = diagonal + (a[i - 1] != b[j - 1]);
      diagonal = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, substitution});
    }
  }
  return row[b.size()];
}

}  // namespace imubridge::estimator
