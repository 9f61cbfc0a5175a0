#pragma once
// Switchable extra effects, each "NAME=VALUE" (the CLI's --effect). A value is one number or a comma-separated list;
// "per axis or all" effects take 1 or 3 numbers. An effect sets its parameter, replacing the scenario's value.
#include <span>
#include <string_view>

#include "sim/simulator.hpp"

namespace imubridge::sim {

struct EffectInfo {
  std::string_view name;
  std::string_view value;    // what VALUE looks like, e.g. "N,E[,D]"
  std::string_view meaning;  // with units
};

// Every effect, in a fixed order (for --help and docs).
std::span<const EffectInfo> effect_catalogue();

// Applies "NAME=VALUE" to `config`. Throws std::invalid_argument with a one-line message naming the problem and
// listing the valid effects.
void apply_effect(SimConfig& config, std::string_view spec);

}  // namespace imubridge::sim
