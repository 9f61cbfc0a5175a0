#pragma once
// PARAMS.json: the model parameters and how they were identified. Values are SI (m, s, rad, 1/s, 1/m, m/s^2); each
// angle also appears in degrees beside its radians for people (beta_deg, alpha_deg, mounting_deg,
// wind_heading_deg). The defaults disable compensation until an identification fills them in.
#include <cstdint>
#include <filesystem>
#include <map>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "estimator/full_model.hpp"
#include "estimator/imu_series.hpp"
#include "estimator/paper_model.hpp"

namespace imubridge::estimator {

inline constexpr int kParamsVersion = 1;

// Filled by the identification; empty means "not identified".
struct Identification {
  std::string method;                          // e.g. "ga", "lm", "ga+lm"
  std::uint64_t seed = 0;                      // seed of a stochastic method, so the run can be repeated
  std::vector<TimeWindow> fit_windows;         // data the parameters were fitted on
  std::vector<TimeWindow> validation_windows;  // held-out data
  std::map<std::string, double> std_errors;    // by parameter path: "paper.x.r", "full.lever_arm.0", ...
  std::map<std::string, double> rmse;          // m/s^2, by channel and data set: "paper.x.fit", "full.y.validation"
  // The drag-velocity filter's process noise (m/s^2/sqrt(Hz)) when the identification fitted it (the filter error
  // method: docs/identification.md); 0: not fitted, the filter's default applies.
  double process_noise = 0.0;
  // s: the reference velocity's delay behind the IMU that the reference was shifted by before fitting and scoring
  // (declared or estimated: docs/identification.md, "Reference delay"); absent when there was no reference.
  std::optional<double> reference_delay{};
  // m/s^2: the accelerometer offset a flight carries that the calibration was not fitted on, measured on the flights
  // that validated it (the std that makes the filter's NEES 2 there: estimator::measure_transfer_offset); absent when
  // not measured (one flight, or validating flights without a reference), and kTransferredOffsetStd applies.
  std::optional<double> transfer_offset_std;

  friend bool operator==(const Identification&, const Identification&) = default;
};

// PARAMS.json keeps apart what belongs to the vehicle from what belongs to one flight (docs/identification.md,
// "Calibration and conditions"). The vehicle's calibration transfers to its next flight: lever arm, mounting, drag,
// accelerometer scale and cross-coupling, and the accelerometer-gyro time offset (the device's own filters). The
// conditions of the flight it was fitted on do not: the wind, and the accelerometer and gyro biases (they change
// from one power-up to the next; the live filter tracks the gyro's). They sit in FullModelParams beside the rest,
// as the estimator runs them, and in PARAMS.json's "conditions" object with the flight they were fitted on.
struct ModelParams {
  PaperAxisParams paper_x;  // pitch: the paper's x-axis model
  PaperAxisParams paper_y;  // roll: the same model about x_b (paper_model.hpp has the sign mapping)
  FullModelParams full;
  // The flight the conditions in `full` were fitted on (estimator::flight_identity of its samples as stored: set by
  // whoever read the flight, replay::SessionSeries::flight; a fit sees a series already cut and turned, so it cannot);
  // empty: not recorded (a file written before conditions were kept apart, by hand, or by a fit no store fed), and
  // they are then taken as they are.
  std::string conditions_flight;
  // Flown on a flight other than conditions_flight (for_flight): that flight's accelerometer offset is unknown, and the
  // filter says so in its variance (config_for, kTransferredOffsetStd). Written with the run's parameters, so a replay
  // estimates as the live run did.
  bool transferred = false;
  // The names of diagnose's effects the model includes, in the order diagnose added them (docs/effects.md): what
  // the model was built from. What each adds to the live estimator is in `full` (Effect::to_live), so the estimator
  // needs no list of them.
  std::vector<std::string> effects;
  // The effects of the model the live estimator cannot run, each with why (diagnose's Effect::live_refusal):
  // written so, a file is refused when read, with that reason, so that no filter flies a model it lacks a part of.
  std::map<std::string, std::string> not_live;
  Identification identification;

  friend bool operator==(const ModelParams&, const ModelParams&) = default;
};

// The conditions `params` hold, in a line a person reads ("wind 3.1 m/s, accelerometer bias 0.21 m/s^2"); empty when
// there are none.
std::string describe_conditions(const FullModelParams& params);
// The parameters to fly `flight` with (a flight_identity, or empty for a live flight no store has yet): unchanged
// when their conditions were fitted on that flight or name none; else the vehicle's calibration alone, and `left`
// (when given) says which conditions were left behind. A calibration from Monday does not fly Tuesday with Monday's
// wind.
ModelParams for_flight(const ModelParams& params, std::string_view flight, std::string* left = nullptr);
// The parameters as they fly any flight they were not fitted on, whatever flight their conditions name (or none,
// for a fit still under way): the vehicle's calibration alone, `transferred`. for_flight's other flight.
ModelParams on_another_flight(const ModelParams& params);

// Reading is strict. It fills missing keys with the defaults (so files written before a key existed still read)
// and takes radians or degrees when only one is given. It throws std::invalid_argument, naming the key's path
// ("full.accel_cross"), for: an unknown key (with "did you mean" the nearest valid one when it is close), a value
// of the wrong type (with the type expected), radians and degrees that disagree, a value out of range
// (validate()), an effect the live estimator does not run (`not_live`) and another version.
void to_json(nlohmann::json& j, const PaperAxisParams& p);
void from_json(const nlohmann::json& j, PaperAxisParams& p);
void to_json(nlohmann::json& j, const FullModelParams& p);
void from_json(const nlohmann::json& j, FullModelParams& p);
void to_json(nlohmann::json& j, const Identification& id);
void from_json(const nlohmann::json& j, Identification& id);
void to_json(nlohmann::json& j, const ModelParams& p);
void from_json(const nlohmann::json& j, ModelParams& p);

// PARAMS.json text (a file, a run's params) as parameters; `origin` names it in the std::invalid_argument thrown.
ModelParams parse_params(std::string_view json_text, const std::string& origin);
// PARAMS.json as `imubridge identify` writes it. Throws std::invalid_argument naming the file and what is wrong.
ModelParams load_params(const std::filesystem::path& path);
// PARAMS.json, indented, to `path`. Throws std::runtime_error when it cannot be written.
void save_params(const std::filesystem::path& path, const ModelParams& params);

}  // namespace imubridge::estimator
