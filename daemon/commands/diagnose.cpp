// `imubridge diagnose`: fit the base model to a recorded session, analyse what its residual still holds, add the
// library's effects one at a time while they lower the validation error significantly, and write DIR/report.json
// and DIR/report.html (docs/effects.md, docs/diagnose.md). A short summary for people goes to stderr.
#include <CLI/CLI.hpp>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "daemon/command.hpp"
#include "diagnose/report.hpp"
#include "diagnose/search.hpp"
#include "estimator/identify.hpp"
#include "pipeline/session_series.hpp"
#include "store/store.hpp"

namespace imubridge::cli {
namespace {

namespace dg = imubridge::diagnose;
namespace est = imubridge::estimator;

struct DiagnoseCliOptions {
  std::string db, report;
  std::int64_t session = 0;
  std::optional<std::int64_t> link;
  std::string axis = "both", model = "paper";
  std::optional<std::string> velocity, train, validate;
  std::vector<std::string> ignore_bands;
  int max_steps = 8;
  double lowpass_hz = 0.0;
};

std::vector<int> parse_axes(const std::string& text) {
  if (text == "x") return {0};
  if (text == "y") return {1};
  if (text == "both") return {0, 1};
  throw std::invalid_argument("unknown axis \"" + text + "\" (valid: x, y, both)");
}

dg::BaseModel parse_model(const std::string& text) {
  if (text == "paper") return dg::BaseModel::kPaper;
  if (text == "full") return dg::BaseModel::kFull;
  throw std::invalid_argument("unknown model \"" + text + "\" (valid: paper, full)");
}

dg::VelocitySource parse_velocity(const std::string& text) {
  if (text == "reference") return dg::VelocitySource::kReference;
  if (text == "imu") return dg::VelocitySource::kImu;
  throw std::invalid_argument("unknown velocity source \"" + text + "\" (valid: reference, imu)");
}

// "F0:F1" in Hz, 0 <= F0 < F1.
std::pair<double, double> parse_band(const std::string& text) {
  const auto number = [](std::string_view piece, double& x) {
    const auto [end, error] = std::from_chars(piece.data(), piece.data() + piece.size(), x);
    return error == std::errc() && end == piece.data() + piece.size() && std::isfinite(x);
  };
  const std::size_t colon = text.find(':');
  double lo = 0.0, hi = 0.0;
  const std::string_view view(text);
  if (colon == std::string::npos || !number(view.substr(0, colon), lo) || !number(view.substr(colon + 1), hi) ||
      !(lo >= 0.0 && lo < hi))
    throw std::invalid_argument("bad band \"" + text + "\" for --ignore-band (expected F0:F1 in Hz, 0 <= F0 < F1)");
  return {lo, hi};
}

void print_params(const std::vector<dg::ParameterEstimate>& params) {
  for (const dg::ParameterEstimate& p : params)
    std::fprintf(stderr, "    %-16s %12.6g ± %-10.3g %s\n", p.name.c_str(), p.value, p.std_error, p.unit.c_str());
}

void print_summary(const dg::Diagnosis& d, const std::string& report) {
  std::fprintf(stderr, "diagnosed %s: %s model, axes", d.session.c_str(), d.model.c_str());
  for (const std::string& a : d.axes) std::fprintf(stderr, " %s", a.c_str());
  std::fprintf(stderr, ", velocity %s; train %.3f:%.3f s, validate %.3f:%.3f s\n", d.velocity_source.c_str(),
               d.train_start, d.train_end, d.validate_start, d.validate_end);
  std::fprintf(stderr, "base: RMSE train %.4f, validation %.4f m/s^2\n", d.base.rmse_train, d.base.rmse_validation);
  print_params(d.base.base_params);
  for (std::size_t i = 0; i < d.steps.size(); ++i) {
    const dg::Step& s = d.steps[i];
    std::fprintf(stderr, "step %zu: + %s: RMSE train %.4f -> %.4f, validation %.4f -> %.4f m/s^2\n", i + 1,
                 s.effect.c_str(), s.rmse_train_before, s.fit.rmse_train, s.rmse_validation_before,
                 s.fit.rmse_validation);
    print_params(s.params);
  }
  if (!d.last_candidates.empty()) {
    const dg::CandidateTrial& best = d.last_candidates.front();
    if (best.skipped.empty())
      std::fprintf(stderr, "stopped: the best candidate, %s (validation %.4f m/s^2, p = %.3g), is not significant\n",
                   best.effect.c_str(), best.rmse_validation, best.p_value);
  }
  std::fprintf(stderr, "final residual %s\n", d.residual_white ? "white" : "NOT white");
  for (const dg::Unexplained& u : d.unexplained)
    std::fprintf(stderr, "  unexplained (%s, axis %s): %s\n", u.kind.c_str(), u.axis.c_str(), u.where.c_str());
  std::fprintf(stderr, "wrote %s/report.json and %s/report.html\n", report.c_str(), report.c_str());
}

int run(const DiagnoseCliOptions& o) {
  dg::DiagnoseOptions options;
  options.model = parse_model(o.model);
  options.axes = parse_axes(o.axis);
  if (o.velocity) options.velocity = parse_velocity(*o.velocity);
  if (o.train) options.train = est::parse_window(*o.train);
  if (o.validate) options.validate = est::parse_window(*o.validate);
  for (const std::string& band : o.ignore_bands) options.ignore_bands.push_back(parse_band(band));
  if (o.max_steps < 0) throw std::invalid_argument("--max-steps must be 0 or more");
  options.max_steps = o.max_steps;
  if (o.lowpass_hz < 0.0) throw std::invalid_argument("--lowpass must be a positive frequency in Hz (0: off)");
  options.lowpass_hz = o.lowpass_hz;
  options.session = o.db + "#" + std::to_string(o.session);

  const store::Store store(o.db, {.read_only = true});
  // The reference when the session has one, unless told otherwise.
  using pipeline::ReferenceUse;
  const ReferenceUse reference = !o.velocity                                           ? ReferenceUse::when_present
                                 : *options.velocity == dg::VelocitySource::kReference ? ReferenceUse::required
                                                                                       : ReferenceUse::none;
  const pipeline::SessionSeries session =
      pipeline::read_session_series(store, o.session, {.link = o.link, .reference = reference});
  options.velocity = session.series.reference ? dg::VelocitySource::kReference : dg::VelocitySource::kImu;
  const dg::Diagnosis diagnosis = dg::run_diagnosis(session.series, options);

  const std::filesystem::path dir(o.report);
  std::filesystem::create_directories(dir);
  dg::write_report_json(diagnosis, dir / "report.json");
  dg::write_report_html(diagnosis, dir);
  print_summary(diagnosis, o.report);
  return 0;
}

const RegisterCommand kDiagnose([](CLI::App& app) -> CommandRunner {
  auto o = std::make_shared<DiagnoseCliOptions>();
  auto* cmd = app.add_subcommand("diagnose",
                                 "Find what the accelerometer model misses: fit it, analyse the residual, add effects");
  cmd->add_option("--db", o->db, "Session store (SQLite), opened read-only")->required();
  cmd->add_option("--session", o->session, "Session id")->required();
  cmd->add_option("--link", o->link, "Link id (default: the session's link with the most samples)");
  cmd->add_option("--axis", o->axis, "x | y | both")->capture_default_str();
  cmd->add_option("--model", o->model, "Base model: paper (eq. 14 per axis) | full (3-D rigid body and mounting)")
      ->capture_default_str();
  cmd->add_option("--velocity", o->velocity,
                  "reference | imu (integrated from the gyro, eq. 12); default: reference when the session has one");
  cmd->add_option("--train", o->train, "Fit window T0:T1 in seconds from the session start (default 0:33)");
  cmd->add_option("--validate", o->validate, "Validation window T0:T1 (default: from the end of --train on)");
  cmd->add_option("--ignore-band", o->ignore_bands, "F0:F1 in Hz the frequency search ignores, repeatable");
  cmd->add_option("--max-steps", o->max_steps, "Effects added at most")->capture_default_str();
  cmd->add_option("--lowpass", o->lowpass_hz,
                  "Compare model and measurement below this frequency only, Hz (0: off); for airframes whose "
                  "vibration swamps the accelerometers")
      ->capture_default_str();
  cmd->add_option("--report", o->report, "Directory for report.json and report.html (created if needed)")->required();
  return [o] { return run(*o); };
});

}  // namespace
}  // namespace imubridge::cli
