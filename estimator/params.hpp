#pragma once
// PARAMS.json: the model parameters and how they were identified. Values are SI (m, s, rad, 1/s, 1/m, m/s^2); each
// angle also appears in degrees beside its radians for people (beta_deg, alpha_deg, mounting_deg). The defaults
// disable compensation until an identification fills them in.
#include <cstdint>
#include <map>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

#include "estimator/full_model.hpp"
#include "estimator/paper_model.hpp"

namespace imubridge::estimator {

inline constexpr int kParamsVersion = 1;

struct TimeWindow {
  double start = 0.0;  // s, session time
  double end = 0.0;    // s, exclusive

  friend bool operator==(const TimeWindow&, const TimeWindow&) = default;
};

// Filled by the identification; empty means "not identified".
struct Identification {
  std::string method;                          // e.g. "ga", "lm", "ga+lm"
  std::uint64_t seed = 0;                      // seed of a stochastic method, so the run can be repeated
  std::vector<TimeWindow> fit_windows;         // data the parameters were fitted on
  std::vector<TimeWindow> validation_windows;  // held-out data
  std::map<std::string, double> std_errors;    // by parameter path: "paper.x.r", "full.lever_arm.0", ...
  std::map<std::string, double> rmse;          // m/s^2, by channel and data set: "paper.x.fit", "full.y.validation"

  friend bool operator==(const Identification&, const Identification&) = default;
};

struct ModelParams {
  PaperAxisParams paper_x;  // pitch: the paper's x-axis model
  PaperAxisParams paper_y;  // roll: the same model about x_b (paper_model.hpp has the sign mapping)
  FullModelParams full;
  Identification identification;

  friend bool operator==(const ModelParams&, const ModelParams&) = default;
};

// Reading fills missing keys with the defaults, takes radians over degrees when only one is given, and throws
// std::invalid_argument when both are given and disagree, when a value is out of range (validate()) or when the
// file is of another version. A wrongly typed value throws nlohmann::json::type_error.
void to_json(nlohmann::json& j, const PaperAxisParams& p);
void from_json(const nlohmann::json& j, PaperAxisParams& p);
void to_json(nlohmann::json& j, const FullModelParams& p);
void from_json(const nlohmann::json& j, FullModelParams& p);
void to_json(nlohmann::json& j, const Identification& id);
void from_json(const nlohmann::json& j, Identification& id);
void to_json(nlohmann::json& j, const ModelParams& p);
void from_json(const nlohmann::json& j, ModelParams& p);

}  // namespace imubridge::estimator
