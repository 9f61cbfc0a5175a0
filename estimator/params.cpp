#include "estimator/params.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <string_view>

#include "estimator/constants.hpp"
#include "estimator/edit_distance.hpp"
#include "fileio/whole_file.hpp"

namespace imubridge::estimator {
namespace {

using nlohmann::json;

constexpr double kDegPerRad = 180.0 / kPi;
// Degrees are written from the radians at full precision, so a round trip agrees far below this; a larger
// difference means a person edited one and not the other.
constexpr double kAngleAgreement = 1e-9;  // rad

constexpr std::array<std::string_view, 7> kTopKeys = {"version", "paper",    "full",          "conditions",
                                                      "effects", "not_live", "identification"};
// The flight's conditions (params.hpp): written in "conditions", still read from "full" in files written before.
constexpr std::array<std::string_view, 7> kConditionKeys = {
    "flight", "transferred", "wind", "wind_heading", "wind_heading_deg", "accel_bias", "gyro_bias"};
constexpr std::array<std::string_view, 2> kPaperKeys = {"x", "y"};
constexpr std::array<std::string_view, 6> kPaperAxisKeys = {"r", "beta", "beta_deg", "alpha", "alpha_deg", "mu"};
constexpr std::array<std::string_view, 13> kFullKeys = {
    "lever_arm",   "mounting",  "mounting_deg", "drag_linear", "drag_quadratic", "accel_bias",      "accel_scale",
    "accel_cross", "gyro_bias", "time_offset",  "wind",        "wind_heading",   "wind_heading_deg"};
constexpr std::array<std::string_view, 9> kIdentificationKeys = {
    "method", "seed",          "fit_windows",     "validation_windows", "std_errors",
    "rmse",   "process_noise", "reference_delay", "transfer_offset_std"};

std::string join(const std::string& path, std::string_view key) {
  return path.empty() ? std::string(key) : path + "." + std::string(key);
}

// The valid name nearest `name`, when it is near enough to be a typo: a third of its length, at least 2 edits.
template <std::size_t N>
std::optional<std::string_view> nearest(std::string_view name, const std::array<std::string_view, N>& valid) {
  std::optional<std::string_view> best;
  std::size_t best_distance = 0;
  for (const std::string_view candidate : valid) {
    const std::size_t d = edit_distance(name, candidate);
    if (!best || d < best_distance) {
      best = candidate;
      best_distance = d;
    }
  }
  if (best && best_distance <= std::max<std::size_t>(2, best->size() / 3)) return best;
  return std::nullopt;
}

template <std::size_t N>
std::string listing(const std::array<std::string_view, N>& valid) {
  std::string out;
  for (const std::string_view v : valid) out += (out.empty() ? "" : ", ") + std::string(v);
  return out;
}

[[noreturn]] void wrong_type(const std::string& path, std::string_view expected, const json& got) {
  throw std::invalid_argument("PARAMS.json: " + path + ": expected " + std::string(expected) + ", got " +
                              got.type_name());
}

// Strict reading: a misspelt key would otherwise be a silently ignored parameter, and the default it leaves
// (no drag, no bias) is a valid model.
template <std::size_t N>
void check_object(const json& j, const std::string& path, const std::array<std::string_view, N>& valid) {
  if (!j.is_object()) wrong_type(path.empty() ? "(top level)" : path, "an object", j);
  for (const auto& item : j.items()) {
    if (std::find(valid.begin(), valid.end(), item.key()) != valid.end()) continue;
    std::string message = "PARAMS.json: unknown key \"" + join(path, item.key()) + "\"";
    if (const auto guess = nearest(item.key(), valid))
      message += " (did you mean \"" + join(path, *guess) + "\"?)";
    else
      message += " (valid keys" + (path.empty() ? std::string() : " in " + path) + ": " + listing(valid) + ")";
    throw std::invalid_argument(message);
  }
}

// The value, converted by nlohmann, with its type errors named by key path.
template <typename T>
T get(const json& j, const std::string& path, std::string_view expected) {
  try {
    return j.get<T>();
  } catch (const json::exception&) {
    wrong_type(path, expected, j);
  }
}

double number(const json& j, const std::string& path) {
  if (!j.is_number()) wrong_type(path, "a number", j);
  return j.get<double>();
}

template <int N>
Eigen::Matrix<double, N, 1> vector(const json& j, const std::string& path) {
  const bool ok =
      j.is_array() && j.size() == N && std::all_of(j.begin(), j.end(), [](const json& v) { return v.is_number(); });
  if (!ok) wrong_type(path, "an array of " + std::to_string(N) + " numbers", j);
  Eigen::Matrix<double, N, 1> out;
  for (int i = 0; i < N; ++i) out[i] = j[static_cast<std::size_t>(i)].template get<double>();
  return out;
}

Eigen::Matrix3d matrix3(const json& j, const std::string& path) {
  if (!j.is_array() || j.size() != 3) wrong_type(path, "an array of 3 rows of 3 numbers", j);
  Eigen::Matrix3d out;
  for (int row = 0; row < 3; ++row) {
    const json& r = j[static_cast<std::size_t>(row)];
    if (!r.is_array() || r.size() != 3 || !std::all_of(r.begin(), r.end(), [](const json& v) { return v.is_number(); }))
      wrong_type(path, "an array of 3 rows of 3 numbers", j);
    for (int col = 0; col < 3; ++col) out(row, col) = r[static_cast<std::size_t>(col)].get<double>();
  }
  return out;
}

template <int N>
json to_array(const Eigen::Matrix<double, N, 1>& v) {
  return json(std::vector<double>(v.data(), v.data() + N));
}

json to_rows(const Eigen::Matrix3d& m) {
  json out = json::array();
  for (int row = 0; row < 3; ++row) out.push_back(to_array<3>(m.row(row).transpose()));
  return out;
}

double largest_difference(double a, double b) { return std::abs(a - b); }
double largest_difference(const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return (a - b).cwiseAbs().maxCoeff(); }

// An angle (scalar or vector) stored as `key` in radians and `key`_deg in degrees; either may be missing.
template <typename Angle, typename Read>
Angle angle_at(const json& j, const std::string& path, const std::string& key, const Angle& fallback, Read read) {
  const std::string deg_key = key + "_deg";
  const bool has_rad = j.contains(key);
  const bool has_deg = j.contains(deg_key);
  if (!has_deg) return has_rad ? read(j.at(key), join(path, key)) : fallback;
  const Angle from_deg = read(j.at(deg_key), join(path, deg_key)) / kDegPerRad;
  if (!has_rad) return from_deg;
  const Angle value = read(j.at(key), join(path, key));
  if (largest_difference(value, from_deg) > kAngleAgreement)
    throw std::invalid_argument("PARAMS.json: " + join(path, key) + " and " + join(path, deg_key) + " disagree");
  return value;
}

template <typename Params>
void throw_if_invalid(const Params& p, const std::string& path) {
  if (auto error = validate(p)) throw std::invalid_argument("PARAMS.json " + path + ": " + *error);
}

json windows_to_json(const std::vector<TimeWindow>& windows) {
  json out = json::array();
  for (const TimeWindow& w : windows) out.push_back({w.start, w.end});
  return out;
}

std::vector<TimeWindow> windows_at(const json& j, const std::string& path) {
  std::vector<TimeWindow> out;
  if (!j.is_array()) wrong_type(path, "an array of [start, end] pairs", j);
  for (const json& pair : j) {
    const Eigen::Vector2d w = vector<2>(pair, path + "[]");
    if (!(w[0] < w[1])) throw std::invalid_argument("PARAMS.json: empty window in " + path);
    out.push_back({w[0], w[1]});
  }
  return out;
}

std::map<std::string, double> numbers_by_name(const json& j, const std::string& path) {
  if (!j.is_object()) wrong_type(path, "an object of numbers", j);
  std::map<std::string, double> out;
  for (const auto& item : j.items()) out[item.key()] = number(item.value(), join(path, item.key()));
  return out;
}

PaperAxisParams read_paper_axis(const json& j, const std::string& path) {
  check_object(j, path, kPaperAxisKeys);
  const PaperAxisParams d;
  PaperAxisParams p;
  p.r = j.contains("r") ? number(j.at("r"), join(path, "r")) : d.r;
  p.beta = angle_at(j, path, "beta", d.beta, number);
  p.alpha = angle_at(j, path, "alpha", d.alpha, number);
  p.mu = j.contains("mu") ? number(j.at("mu"), join(path, "mu")) : d.mu;
  throw_if_invalid(p, path);
  return p;
}

FullModelParams read_full(const json& j, const std::string& path) {
  check_object(j, path, kFullKeys);
  FullModelParams p;  // the defaults stand for missing keys
  const auto at = [&](const char* key, auto& field, auto read) {
    if (j.contains(key)) field = read(j.at(key), join(path, key));
  };
  at("lever_arm", p.lever_arm, vector<3>);
  p.mounting = angle_at<Eigen::Vector3d>(j, path, "mounting", p.mounting, vector<3>);
  at("drag_linear", p.drag_linear, vector<2>);
  at("drag_quadratic", p.drag_quadratic, vector<2>);
  at("accel_bias", p.accel_bias, vector<3>);
  at("accel_scale", p.accel_scale, vector<3>);
  at("accel_cross", p.accel_cross, matrix3);
  at("gyro_bias", p.gyro_bias, vector<3>);
  at("time_offset", p.time_offset, number);
  at("wind", p.wind, vector<2>);
  p.wind_heading = angle_at(j, path, "wind_heading", p.wind_heading, number);
  throw_if_invalid(p, path);
  return p;
}

// The conditions object over `p`'s, and the flight they belong to.
void read_conditions(const json& j, const std::string& path, FullModelParams& p, std::string& flight,
                     bool& transferred) {
  check_object(j, path, kConditionKeys);
  if (j.contains("flight")) flight = get<std::string>(j.at("flight"), join(path, "flight"), "a string");
  if (j.contains("transferred"))
    transferred = get<bool>(j.at("transferred"), join(path, "transferred"), "true or false");
  if (j.contains("wind")) p.wind = vector<2>(j.at("wind"), join(path, "wind"));
  p.wind_heading = angle_at(j, path, "wind_heading", p.wind_heading, number);
  if (j.contains("accel_bias")) p.accel_bias = vector<3>(j.at("accel_bias"), join(path, "accel_bias"));
  if (j.contains("gyro_bias")) p.gyro_bias = vector<3>(j.at("gyro_bias"), join(path, "gyro_bias"));
  throw_if_invalid(p, path);
}

Identification read_identification(const json& j, const std::string& path) {
  check_object(j, path, kIdentificationKeys);
  Identification id;
  if (j.contains("method")) id.method = get<std::string>(j.at("method"), join(path, "method"), "a string");
  if (j.contains("seed")) {
    const json& seed = j.at("seed");
    if (!seed.is_number_unsigned()) wrong_type(join(path, "seed"), "an unsigned integer", seed);
    id.seed = seed.get<std::uint64_t>();
  }
  if (j.contains("fit_windows")) id.fit_windows = windows_at(j.at("fit_windows"), join(path, "fit_windows"));
  if (j.contains("validation_windows"))
    id.validation_windows = windows_at(j.at("validation_windows"), join(path, "validation_windows"));
  if (j.contains("std_errors")) id.std_errors = numbers_by_name(j.at("std_errors"), join(path, "std_errors"));
  if (j.contains("rmse")) id.rmse = numbers_by_name(j.at("rmse"), join(path, "rmse"));
  if (j.contains("process_noise")) {
    id.process_noise = get<double>(j.at("process_noise"), join(path, "process_noise"), "a number");
    if (!(id.process_noise >= 0.0) || !std::isfinite(id.process_noise))
      throw std::invalid_argument("PARAMS.json: " + join(path, "process_noise") +
                                  " must be a finite number >= 0 (m/s^2/sqrt(Hz); 0: the filter's default)");
  }
  if (j.contains("reference_delay")) {
    id.reference_delay = get<double>(j.at("reference_delay"), join(path, "reference_delay"), "a number");
    if (!std::isfinite(*id.reference_delay))
      throw std::invalid_argument("PARAMS.json: " + join(path, "reference_delay") + " must be a finite number (s)");
  }
  if (j.contains("transfer_offset_std")) {
    id.transfer_offset_std = get<double>(j.at("transfer_offset_std"), join(path, "transfer_offset_std"), "a number");
    if (!(*id.transfer_offset_std >= 0.0) || !std::isfinite(*id.transfer_offset_std))
      throw std::invalid_argument("PARAMS.json: " + join(path, "transfer_offset_std") +
                                  " must be a finite number >= 0 (m/s^2)");
  }
  return id;
}

std::vector<std::string> read_effects(const json& j, const std::string& path) {
  if (!j.is_array()) wrong_type(path, "an array of effect names", j);
  std::vector<std::string> out;
  for (const json& name : j) {
    if (!name.is_string()) wrong_type(path + "[]", "an effect name (a string)", name);
    out.push_back(name.get<std::string>());
  }
  return out;
}

// A model with an effect the live estimator cannot run is refused, with the reason diagnose wrote for it.
void refuse_not_live(const json& j, const std::string& path) {
  if (!j.is_object()) wrong_type(path, "an object of effect names and reasons", j);
  for (const auto& [name, why] : j.items()) {
    if (!why.is_string()) wrong_type(join(path, name), "the reason (a string)", why);
    throw std::invalid_argument("PARAMS.json: " + join(path, name) +
                                ": the live estimator cannot run it: " + why.get<std::string>());
  }
}

}  // namespace

std::string describe_conditions(const FullModelParams& p) {
  std::string out;
  const auto add = [&](const char* what, double size, const char* unit) {
    if (size == 0.0) return;
    char text[96];
    std::snprintf(text, sizeof text, "%s%s %.3g %s", out.empty() ? "" : ", ", what, size, unit);
    out += text;
  };
  add("wind", p.wind.norm(), "m/s");
  add("accelerometer bias", p.accel_bias.norm(), "m/s^2");
  add("gyro bias", p.gyro_bias.norm(), "rad/s");
  return out;
}

ModelParams on_another_flight(const ModelParams& params) {
  ModelParams out = params;
  out.transferred = true;
  out.full.wind.setZero();
  out.full.wind_heading = 0.0;
  out.full.accel_bias.setZero();
  out.full.gyro_bias.setZero();
  return out;
}

ModelParams for_flight(const ModelParams& params, std::string_view flight, std::string* left) {
  if (params.conditions_flight.empty() || params.conditions_flight == flight) return params;
  const ModelParams out = on_another_flight(params);
  const std::string conditions = describe_conditions(params.full);
  if (left != nullptr && !conditions.empty()) {
    *left = "the conditions of the flight these parameters were fitted on (" + params.conditions_flight + ": " +
            conditions + ") are left behind; this flight starts from the vehicle's calibration alone";
  }
  return out;
}

void to_json(json& j, const PaperAxisParams& p) {
  j = json{{"r", p.r},
           {"beta", p.beta},
           {"beta_deg", p.beta * kDegPerRad},
           {"alpha", p.alpha},
           {"alpha_deg", p.alpha * kDegPerRad},
           {"mu", p.mu}};
}

void from_json(const json& j, PaperAxisParams& p) { p = read_paper_axis(j, "paper"); }

void to_json(json& j, const FullModelParams& p) {
  j = json{{"lever_arm", to_array(p.lever_arm)},
           {"mounting", to_array(p.mounting)},
           {"mounting_deg", to_array<3>(p.mounting * kDegPerRad)},
           {"drag_linear", to_array(p.drag_linear)},
           {"drag_quadratic", to_array(p.drag_quadratic)},
           {"accel_scale", to_array(p.accel_scale)},
           {"accel_cross", to_rows(p.accel_cross)},
           {"time_offset", p.time_offset}};
}

void from_json(const json& j, FullModelParams& p) { p = read_full(j, "full"); }

void to_json(json& j, const Identification& id) {
  j = json{{"method", id.method},
           {"seed", id.seed},
           {"fit_windows", windows_to_json(id.fit_windows)},
           {"validation_windows", windows_to_json(id.validation_windows)},
           {"std_errors", id.std_errors},
           {"rmse", id.rmse},
           {"process_noise", id.process_noise}};
  if (id.reference_delay) j["reference_delay"] = *id.reference_delay;
  if (id.transfer_offset_std) j["transfer_offset_std"] = *id.transfer_offset_std;
}

void from_json(const json& j, Identification& id) { id = read_identification(j, "identification"); }

void to_json(json& j, const ModelParams& p) {
  const FullModelParams& f = p.full;
  j = json{{"version", kParamsVersion},
           {"paper", {{"x", p.paper_x}, {"y", p.paper_y}}},
           {"full", f},
           {"conditions",
            {{"flight", p.conditions_flight},
             {"transferred", p.transferred},
             {"wind", to_array(f.wind)},
             {"wind_heading", f.wind_heading},
             {"wind_heading_deg", f.wind_heading * kDegPerRad},
             {"accel_bias", to_array(f.accel_bias)},
             {"gyro_bias", to_array(f.gyro_bias)}}},
           {"effects", p.effects},
           {"identification", p.identification}};
  if (!p.not_live.empty()) j["not_live"] = p.not_live;
}

void from_json(const json& j, ModelParams& p) {
  check_object(j, "", kTopKeys);
  if (j.contains("version")) {
    const json& version = j.at("version");
    if (!version.is_number_integer()) wrong_type("version", "an integer", version);
    if (version.get<std::int64_t>() != kParamsVersion)
      throw std::invalid_argument("PARAMS.json: unsupported version " + version.dump());
  }
  p = ModelParams{};
  if (j.contains("paper")) {
    const json& paper = j.at("paper");
    check_object(paper, "paper", kPaperKeys);
    if (paper.contains("x")) p.paper_x = read_paper_axis(paper.at("x"), "paper.x");
    if (paper.contains("y")) p.paper_y = read_paper_axis(paper.at("y"), "paper.y");
  }
  if (j.contains("full")) p.full = read_full(j.at("full"), "full");
  if (j.contains("conditions"))
    read_conditions(j.at("conditions"), "conditions", p.full, p.conditions_flight, p.transferred);
  if (j.contains("effects")) p.effects = read_effects(j.at("effects"), "effects");
  if (j.contains("not_live")) refuse_not_live(j.at("not_live"), "not_live");
  if (j.contains("identification")) p.identification = read_identification(j.at("identification"), "identification");
}

ModelParams parse_params(std::string_view json_text, const std::string& origin) {
  try {
    return json::parse(json_text).get<ModelParams>();
  } catch (const std::exception& e) {  // nlohmann's parse and type errors, and the params' own range checks
    throw std::invalid_argument(origin + " is not valid PARAMS.json: " + e.what());
  }
}

ModelParams load_params(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  if (!in) throw std::invalid_argument(path.string() + ": cannot read the parameters file");
  return parse_params(text.str(), path.string());
}

void save_params(const std::filesystem::path& path, const ModelParams& params) {
  fileio::write_whole_file(path, json(params).dump(2) + "\n");
}

}  // namespace imubridge::estimator
