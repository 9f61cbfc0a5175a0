// report.json and the summary line: every field of a Diagnosis, for programs.
#include "diagnose/report.hpp"

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "diagnose/report_parts.hpp"

namespace imubridge::diagnose {
namespace {

using nlohmann::json;
using report_parts::axis_name;
using report_parts::number;

json numbers(const std::vector<double>& values) {
  json list = json::array();
  for (double v : values) list.push_back(number(v));
  return list;
}

json gyro_json(const std::optional<GyroAgainstReference>& g) {
  if (!g) return nullptr;
  return {{"bias_rad_s", numbers({g->bias.x(), g->bias.y(), g->bias.z()})},
          {"std_error_rad_s", numbers({g->std_error.x(), g->std_error.y(), g->std_error.z()})},
          {"p_value", number(g->p_value)},
          {"spans", g->spans}};
}

json parameter_json(const ParameterEstimate& p) {
  return {{"name", p.name}, {"value", number(p.value)}, {"std_error", number(p.std_error)}, {"unit", p.unit}};
}

json parameters_json(const std::vector<ParameterEstimate>& params) {
  json list = json::array();
  for (const auto& p : params) list.push_back(parameter_json(p));
  return list;
}

// A fit's parameters in one list, each saying which part of the model it belongs to ("base" or the effect).
json fit_parameters_json(const ModelFit& fit) {
  json list = json::array();
  const auto add = [&](const std::vector<ParameterEstimate>& params, const std::string& component) {
    for (const auto& p : params) {
      json entry = parameter_json(p);
      entry["component"] = component;
      list.push_back(std::move(entry));
    }
  };
  add(fit.base_params, "base");
  for (std::size_t i = 0; i < fit.effects.size() && i < fit.effect_params.size(); ++i) {
    add(fit.effect_params[i], fit.effects[i]);
  }
  return list;
}

json score_json(const estimator::VelocityError& s) {
  return {{"x", number(s.axis.x())}, {"y", number(s.axis.y())}, {"horizontal", number(s.horizontal)}};
}

json velocity_json(const std::optional<estimator::VelocityScores>& v) {
  if (!v) return nullptr;
  json out = {{"train", score_json(v->train)}, {"validation", score_json(v->validation)}};
  if (!v->note.empty()) out["note"] = v->note;
  return out;
}

json model_json(const ModelFit& fit) {
  return {{"effects", fit.effects},
          {"params", fit_parameters_json(fit)},
          {"free_parameters", fit.free_parameters},
          {"velocity_rmse_m_s", velocity_json(fit.velocity)},
          {"at_bounds", fit.at_bounds},
          {"implausible", fit.implausible},
          {"convergence", numbers(fit.convergence)}};
}

json residual_json(const ResidualAnalysis& r, const std::string& axis) {
  json peaks = json::array();
  for (std::size_t i = 0; i < r.peaks.size() && i < kReportTopEntries; ++i) {
    const auto& peak = r.peaks[i];
    peaks.push_back({{"frequency_hz", number(peak.frequency_hz)},
                     {"power_ratio", number(peak.power_ratio)},
                     {"ignored", peak.ignored}});
  }
  json correlations = json::array();
  std::size_t significant = 0;
  for (std::size_t i = 0; i < r.correlations.size(); ++i) {
    const auto& c = r.correlations[i];
    significant += c.significant ? 1 : 0;
    if (i >= kReportTopEntries) continue;
    correlations.push_back({{"signal", c.signal},
                            {"lag_s", number(c.lag_s)},
                            {"coefficient", number(c.coefficient)},
                            {"threshold", number(c.threshold)},
                            {"significant", c.significant}});
  }
  return {
      {"axis", axis},
      {"samples", r.samples},
      {"rms", number(r.rms)},
      {"mean", number(r.mean)},
      {"ljung_box",
       {{"lags", r.ljung_box_lags}, {"q", number(r.ljung_box_q)}, {"p", number(r.ljung_box_p)}, {"white", r.white}}},
      {"peaks", std::move(peaks)},
      {"peaks_found", r.peaks.size()},
      {"correlations", std::move(correlations)},
      {"significant_correlations", significant},
      {"trend",
       {{"per_s", number(r.trend_per_s)},
        {"std_error", number(r.trend_std_error)},
        {"significant", r.trend_significant}}}};
}

json residuals_json(const Diagnosis& d, const std::vector<ResidualAnalysis>& residuals) {
  json list = json::array();
  for (std::size_t i = 0; i < residuals.size(); ++i) list.push_back(residual_json(residuals[i], axis_name(d, i)));
  return list;
}

// Every axis white; null when there is no analysis to judge by.
json whiteness(const std::vector<ResidualAnalysis>& residuals) {
  if (residuals.empty()) return nullptr;
  return std::all_of(residuals.begin(), residuals.end(), [](const ResidualAnalysis& r) { return r.white; });
}

// base and final: the fit's fields directly, with its residual.
json fit_json(const Diagnosis& d, const ModelFit& fit, const std::vector<ResidualAnalysis>& residual) {
  json out = model_json(fit);
  out["rmse_train"] = number(fit.rmse_train);
  out["rmse_validation"] = number(fit.rmse_validation);
  out["velocity_rmse_m_s"] = velocity_json(fit.velocity);
  if (fit.likelihood)
    out["likelihood"] = {{"train", number(fit.likelihood->train)}, {"validation", number(fit.likelihood->validation)}};
  out["residual"] = residuals_json(d, residual);
  out["residual_white"] = whiteness(residual);
  return out;
}

json candidates_json(const std::vector<CandidateTrial>& candidates) {
  json list = json::array();
  for (const auto& c : candidates) {
    list.push_back({{"effect", c.effect},
                    {"with", c.with},
                    {"rmse_train", number(c.rmse_train)},
                    {"rmse_validation", number(c.rmse_validation)},
                    {"statistic", number(c.statistic)},
                    {"p_value", number(c.p_value)},
                    {"significant", c.significant},
                    {"velocity_validation_m_s", c.velocity_validation ? number(*c.velocity_validation) : json()},
                    {"likelihood_validation", c.likelihood_validation ? number(*c.likelihood_validation) : json()},
                    {"velocity_test_p", c.velocity_test_p ? number(*c.velocity_test_p) : json()},
                    {"attitude_test_p", c.attitude_test_p ? number(*c.attitude_test_p) : json()},
                    {"admitted_by", c.admitted_by},
                    {"held_at_zero", c.held_at_zero},
                    {"held", c.held},
                    {"rejected_by", c.rejected_by},
                    {"skipped", c.skipped}});
  }
  return list;
}

json step_json(const Diagnosis& d, const Step& step) {
  return {{"effect", step.effect},
          {"with", step.with},
          {"released", step.released},
          {"params", parameters_json(step.params)},
          {"rmse_train", number(step.fit.rmse_train)},
          {"rmse_validation", number(step.fit.rmse_validation)},
          {"rmse_train_before", number(step.rmse_train_before)},
          {"rmse_validation_before", number(step.rmse_validation_before)},
          {"velocity_rmse_m_s", velocity_json(step.fit.velocity)},
          {"residual_white", whiteness(step.residual)},
          {"residual", residuals_json(d, step.residual)},
          {"candidates", candidates_json(step.candidates)},
          {"model", model_json(step.fit)}};
}

json unexplained_json(const Unexplained& u) {
  json out = {{"kind", u.kind}, {"axis", u.axis}, {"where", u.where}, {"value", number(u.value)}};
  if (u.kind == "frequency") out["frequency_hz"] = number(u.frequency_hz);
  if (u.kind == "correlation") out["signal"] = u.signal;
  if (u.kind == "correlation" || u.kind == "autocorrelation") out["lag_s"] = number(u.lag_s);
  return out;
}

}  // namespace

std::string summary_line(const Diagnosis& d) {
  char text[400];
  std::string line;
  if (d.base.velocity && d.final.velocity) {
    std::snprintf(text, sizeof text,
                  "velocity RMSE on the validation window %.3f -> %.3f m/s (horizontal; x %.3f -> %.3f, y %.3f -> %.3f",
                  d.base.velocity->validation.horizontal, d.final.velocity->validation.horizontal,
                  d.base.velocity->validation.axis.x(), d.final.velocity->validation.axis.x(),
                  d.base.velocity->validation.axis.y(), d.final.velocity->validation.axis.y());
    line = text;
    if (d.zero_velocity) {
      std::snprintf(text, sizeof text, "; zero velocity %.3f", d.zero_velocity->validation.horizontal);
      line += text;
    }
    line += ")";
    if (!d.base.velocity->note.empty()) line += " [base: " + d.base.velocity->note + "]";
    if (!d.final.velocity->note.empty()) line += " [final: " + d.final.velocity->note + "]";
    line += "; ";
  } else {
    line = "no reference velocity, so no velocity error; ";
  }
  std::snprintf(text, sizeof text, "specific-force residual %.4f -> %.4f m/s^2; ", d.base.rmse_validation,
                d.final.rmse_validation);
  line += text;
  if (d.steps.empty()) {
    line += "no effect added";
  } else {
    std::vector<std::string> effects;
    for (const auto& step : d.steps) effects.push_back(with_needed(step.effect, step.with));
    line += std::to_string(d.steps.size()) + (d.steps.size() == 1 ? " effect added (" : " effects added (") +
            report_parts::join(effects, ", ") + ")";
  }
  return line;
}

nlohmann::json report_json(const Diagnosis& d) {
  json steps = json::array();
  for (const auto& step : d.steps) steps.push_back(step_json(d, step));
  json unexplained = json::array();
  for (const auto& u : d.unexplained) unexplained.push_back(unexplained_json(u));
  json ramps = json::array();
  for (const VelocityRamp& r : d.velocity_ramps) {
    ramps.push_back({{"axis", r.axis},
                     {"ramp_m_s", number(r.ramp_m_s())},
                     {"span_s", number(r.span_s)},
                     {"per_s", number(r.per_s)},
                     {"std_error", number(r.std_error)},
                     {"named", r.named}});
  }
  json scales = json::object();
  for (const PredictionScale& s : d.prediction_scale) scales[s.axis] = number(s.scale);
  json series = json::array();
  for (const auto& s : d.series) {
    series.push_back({{"axis", s.axis},
                      {"samples", s.t.size()},
                      {"t_start", s.t.empty() ? json(nullptr) : number(s.t.front())},
                      {"t_end", s.t.empty() ? json(nullptr) : number(s.t.back())}});
  }
  return {
      {"session", d.session},
      {"summary", summary_line(d)},
      {"warnings", d.warnings},
      {"imu_axes", d.imu_axes},
      {"zero_velocity_rmse_m_s", velocity_json(d.zero_velocity)},
      {"gyro_against_reference", {{"train", gyro_json(d.gyro_train)}, {"validation", gyro_json(d.gyro_validation)}}},
      {"model", d.model},
      {"axes", d.axes},
      {"velocity_source", d.velocity_source},
      {"train_window", {{"start", number(d.train_start)}, {"end", number(d.train_end)}}},
      {"validation_window", {{"start", number(d.validate_start)}, {"end", number(d.validate_end)}}},
      {"significance_rule", d.significance_rule},
      {"base", fit_json(d, d.base, d.base_residual)},
      {"steps", std::move(steps)},
      {"last_candidates", candidates_json(d.last_candidates)},
      {"final", fit_json(d, d.final, d.final_residual)},
      {"residual_white", d.residual_white},
      {"unexplained", std::move(unexplained)},
      {"velocity_ramps", std::move(ramps)},
      {"prediction_scale", std::move(scales)},
      {"series", std::move(series)}};
}

void write_report_json(const Diagnosis& diagnosis, const std::filesystem::path& file) {
  report_parts::write_text(file, report_json(diagnosis).dump(2) + "\n");
}

std::string with_needed(const std::string& effect, const std::vector<std::string>& with) {
  std::string out = effect;
  for (std::size_t i = 0; i < with.size(); ++i) out += (i == 0 ? " (with " : ", ") + with[i];
  return with.empty() ? out : out + ")";
}

}  // namespace imubridge::diagnose
