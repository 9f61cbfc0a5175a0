#pragma once
// A stored double against what an output wrote for it in JSON: the same value, or null where the store holds NaN
// (JSON has no NaN; the MCAP and Foxglove outputs write null).
#include <cmath>
#include <nlohmann/json.hpp>

namespace imubridge::test {

inline bool json_holds(const nlohmann::json& j, double v) {
  return std::isnan(v) ? j.is_null() : (j.is_number() && j.get<double>() == v);
}

}  // namespace imubridge::test
