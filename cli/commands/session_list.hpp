#pragma once
// Several sessions named at once ("3", "3,5,7", "2-30", "2-30,35"), for commands that score or fit over several
// flights. Order kept, repeats dropped.
#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace imubridge::cli {

inline std::vector<std::int64_t> parse_session_list(std::string_view text) {
  const auto invalid = [&text] {
    return std::invalid_argument("invalid --session \"" + std::string(text) +
                                 "\": give session ids like 3, 3,5,7 or 2-30");
  };
  const auto number = [&](std::string_view digits) {
    if (digits.empty() || digits.size() > 18 ||
        !std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; }))
      throw invalid();
    return static_cast<std::int64_t>(std::stoll(std::string(digits)));
  };
  std::vector<std::int64_t> out;
  const auto add = [&out](std::int64_t id) {
    if (std::find(out.begin(), out.end(), id) == out.end()) out.push_back(id);
  };
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t comma = std::min(text.find(',', start), text.size());
    const std::string_view item = text.substr(start, comma - start);
    if (const std::size_t dash = item.find('-'); dash == std::string_view::npos) {
      add(number(item));
    } else {
      const std::int64_t first = number(item.substr(0, dash)), last = number(item.substr(dash + 1));
      if (last < first || last - first > 100000) throw invalid();
      for (std::int64_t id = first; id <= last; ++id) add(id);
    }
    start = comma + 1;
  }
  return out;
}

}  // namespace imubridge::cli
