#include "estimator/params.hpp"

#include <array>
#include <cmath>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "estimator/constants.hpp"

namespace imubridge::estimator {
namespace {

using nlohmann::json;

constexpr double kDegPerRad = 180.0 / kPi;
// Degrees are written from the radians at full precision, so a round trip agrees far below this; a larger
// difference means a person edited one and not the other.
constexpr double kAngleAgreement = 1e-9;  // rad

template <int N>
json to_array(const Eigen::Matrix<double, N, 1>& v) {
  return json(std::vector<double>(v.data(), v.data() + N));
}

template <int N>
Eigen::Matrix<double, N, 1> vector_at(const json& j, const char* key, const Eigen::Matrix<double, N, 1>& fallback) {
  const auto it = j.find(key);
  if (it == j.end()) return fallback;
  const auto values = it->get<std::array<double, N>>();
  return Eigen::Map<const Eigen::Matrix<double, N, 1>>(values.data());
}

double number_at(const json& j, const char* key, double fallback) {
  const auto it = j.find(key);
  return it == j.end() ? fallback : it->get<double>();
}

double largest_difference(double a, double b) { return std::abs(a - b); }
double largest_difference(const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return (a - b).cwiseAbs().maxCoeff(); }

// An angle (scalar or vector) stored as `key` in radians and `key`_deg in degrees; either may be missing.
template <typename Angle, typename Read>
Angle angle_at(const json& j, const std::string& key, const Angle& fallback, Read read) {
  const std::string deg_key = key + "_deg";
  const bool has_rad = j.contains(key);
  const bool has_deg = j.contains(deg_key);
  if (!has_deg) return has_rad ? read(key.c_str()) : fallback;
  const Angle from_deg = read(deg_key.c_str()) / kDegPerRad;
  if (!has_rad) return from_deg;
  const Angle value = read(key.c_str());
  if (largest_difference(value, from_deg) > kAngleAgreement)
    throw std::invalid_argument("PARAMS.json: " + key + " and " + deg_key + " disagree");
  return value;
}

template <typename Params>
void throw_if_invalid(const Params& p, const char* what) {
  if (auto error = validate(p)) throw std::invalid_argument(std::string("PARAMS.json ") + what + ": " + *error);
}

json windows_to_json(const std::vector<TimeWindow>& windows) {
  json out = json::array();
  for (const TimeWindow& w : windows) out.push_back({w.start, w.end});
  return out;
}

std::vector<TimeWindow> windows_at(const json& j, const char* key) {
  std::vector<TimeWindow> out;
  if (!j.contains(key)) return out;
  for (const auto& pair : j.at(key).get<std::vector<std::array<double, 2>>>()) {
    if (!(pair[0] < pair[1])) throw std::invalid_argument(std::string("PARAMS.json: empty window in ") + key);
    out.push_back({pair[0], pair[1]});
  }
  return out;
}

}  // namespace

void to_json(json& j, const PaperAxisParams& p) {
  j = json{{"r", p.r},
           {"beta", p.beta},
           {"beta_deg", p.beta * kDegPerRad},
           {"alpha", p.alpha},
           {"alpha_deg", p.alpha * kDegPerRad},
           {"mu", p.mu}};
}

void from_json(const json& j, PaperAxisParams& p) {
  const PaperAxisParams d;
  const auto scalar = [&j](const char* key) { return j.at(key).get<double>(); };
  p.r = number_at(j, "r", d.r);
  p.beta = angle_at(j, "beta", d.beta, scalar);
  p.alpha = angle_at(j, "alpha", d.alpha, scalar);
  p.mu = number_at(j, "mu", d.mu);
  throw_if_invalid(p, "paper");
}

void to_json(json& j, const FullModelParams& p) {
  j = json{{"lever_arm", to_array(p.lever_arm)},
           {"mounting", to_array(p.mounting)},
           {"mounting_deg", to_array<3>(p.mounting * kDegPerRad)},
           {"drag_linear", to_array(p.drag_linear)},
           {"drag_quadratic", to_array(p.drag_quadratic)},
           {"accel_bias", to_array(p.accel_bias)}};
}

void from_json(const json& j, FullModelParams& p) {
  const FullModelParams d;
  const auto vector3 = [&j](const char* key) { return vector_at<3>(j, key, Eigen::Vector3d::Zero()); };
  p.lever_arm = vector_at<3>(j, "lever_arm", d.lever_arm);
  p.mounting = angle_at<Eigen::Vector3d>(j, "mounting", d.mounting, vector3);
  p.drag_linear = vector_at<2>(j, "drag_linear", d.drag_linear);
  p.drag_quadratic = vector_at<2>(j, "drag_quadratic", d.drag_quadratic);
  p.accel_bias = vector_at<3>(j, "accel_bias", d.accel_bias);
  throw_if_invalid(p, "full");
}

void to_json(json& j, const Identification& id) {
  j = json{{"method", id.method},
           {"seed", id.seed},
           {"fit_windows", windows_to_json(id.fit_windows)},
           {"validation_windows", windows_to_json(id.validation_windows)},
           {"std_errors", id.std_errors},
           {"rmse", id.rmse}};
}

void from_json(const json& j, Identification& id) {
  id = Identification{};
  if (j.contains("method")) id.method = j.at("method").get<std::string>();
  if (j.contains("seed")) id.seed = j.at("seed").get<std::uint64_t>();
  id.fit_windows = windows_at(j, "fit_windows");
  id.validation_windows = windows_at(j, "validation_windows");
  if (j.contains("std_errors")) id.std_errors = j.at("std_errors").get<std::map<std::string, double>>();
  if (j.contains("rmse")) id.rmse = j.at("rmse").get<std::map<std::string, double>>();
}

void to_json(json& j, const ModelParams& p) {
  j = json{{"version", kParamsVersion},
           {"paper", {{"x", p.paper_x}, {"y", p.paper_y}}},
           {"full", p.full},
           {"identification", p.identification}};
}

void from_json(const json& j, ModelParams& p) {
  if (j.value("version", kParamsVersion) != kParamsVersion)
    throw std::invalid_argument("PARAMS.json: unsupported version " + j.at("version").dump());
  p = ModelParams{};
  const json empty = json::object();
  const json& paper = j.contains("paper") ? j.at("paper") : empty;
  p.paper_x = paper.value("x", empty).get<PaperAxisParams>();
  p.paper_y = paper.value("y", empty).get<PaperAxisParams>();
  p.full = j.value("full", empty).get<FullModelParams>();
  p.identification = j.value("identification", empty).get<Identification>();
}

}  // namespace imubridge::estimator
