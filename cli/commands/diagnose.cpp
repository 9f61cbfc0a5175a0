// `imubridge diagnose`: fit the base model to a recorded session, analyse what its residual still holds, add the
// library's effects one at a time while they lower the validation error significantly, and write DIR/report.json
// and DIR/report.html with --report DIR (docs/effects.md), and with --out the final model as PARAMS.json. A short
// summary for people goes to stdout.
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "cli/command.hpp"
#include "cli/commands/flight_set_reading.hpp"
#include "cli/commands/reference_delay_option.hpp"
#include "cli/commands/session_list.hpp"
#include "cli/commands/session_windows.hpp"
#include "cli/commands/velocity_print.hpp"
#include "diagnose/report.hpp"
#include "diagnose/search.hpp"
#include "estimator/params.hpp"
#include "identification/identify.hpp"
#include "replay/session_series.hpp"
#include "store/store.hpp"

namespace imubridge::cli {
namespace {

namespace dg = imubridge::diagnose;
namespace est = imubridge::estimator;

struct DiagnoseCliOptions {
  std::string db;
  std::optional<std::string> report;
  std::string sessions;
  std::optional<std::string> validate_sessions;
  std::optional<std::int64_t> link;
  std::optional<std::string> imu_axes;
  std::optional<double> reference_delay;
  std::string axis = "both", model = "paper";
  std::optional<std::string> velocity;
  WindowArgs windows;
  std::vector<std::string> ignore_bands, limits;
  std::optional<std::string> out;
  int max_steps = 8;
  bool judge_by_flight = false;
  bool residual_only = false;
  double lowpass_hz = 0.0;
};

std::vector<int> parse_axes(const std::string& text) {
  if (text == "x") return {0};
  if (text == "y") return {1};
  if (text == "both") return {0, 1};
  throw std::invalid_argument("unknown axis \"" + text + "\" (valid: x, y, both)");
}

dg::ModelKind parse_model(const std::string& text) {
  if (text == "paper") return dg::ModelKind::paper;
  if (text == "full") return dg::ModelKind::full;
  throw std::invalid_argument("unknown model \"" + text + "\" (valid: paper, full)");
}

dg::VelocitySource parse_velocity(const std::string& text) {
  if (text == "reference") return dg::VelocitySource::reference;
  if (text == "imu") return dg::VelocitySource::eq12;
  if (text == "filter") return dg::VelocitySource::filter;
  throw std::invalid_argument("unknown velocity source \"" + text + "\" (valid: reference, filter, imu)");
}

// One line on a terminal's stderr, rewritten as the search moves: the step, the candidates being fitted, how many
// are done and the time so far. Called from the fitting threads.
class TerminalProgress {
 public:
  void operator()(const dg::DiagnoseProgress& p) {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (p.step != step_) fitting_.clear(), step_ = p.step;
    if (p.finished) {
      fitting_.erase(std::remove(fitting_.begin(), fitting_.end(), p.candidate), fitting_.end());
    } else {
      fitting_.push_back(p.candidate);
    }
    std::string names;
    for (const std::string& n : fitting_) names += (names.empty() ? "" : ", ") + n;
    if (p.step == 0) {
      std::fprintf(stderr, "\r\033[Kdiagnose: fitting the base model, %.1f s", p.elapsed_s);
    } else {
      std::fprintf(stderr, "\r\033[Kdiagnose: step %d, fitting %s (%zu of %zu candidates done), %.1f s", p.step,
                   names.empty() ? "-" : names.c_str(), p.done, p.total, p.elapsed_s);
    }
    std::fflush(stderr);
  }
  // Clears the line, so that what follows starts on a clean one.
  static void clear() { std::fprintf(stderr, "\r\033[K"), std::fflush(stderr); }

 private:
  std::mutex mutex_;
  int step_ = -1;
  std::vector<std::string> fitting_;
};

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

void print_params(const std::vector<dg::ParameterEstimate>& params, const std::string& std_error_failure = "") {
  bool unknown = false;
  for (const dg::ParameterEstimate& p : params) {
    if (std::isfinite(p.std_error)) {
      std::printf("    %-16s %12.6g ± %-10.3g %s\n", p.name.c_str(), p.value, p.std_error, p.unit.c_str());
    } else {
      std::printf("    %-16s %12.6g ± %-10s %s\n", p.name.c_str(), p.value, "?", p.unit.c_str());
      unknown = true;
    }
  }
  if (unknown)
    std::printf("    (? : no standard error: %s)\n",
                std_error_failure.empty() ? "the covariance could not be computed" : std_error_failure.c_str());
}

// The final model exactly as PARAMS.json holds it (what run, replay and evaluate estimate with): the vehicle's
// calibration, then the flight's conditions, each value with its standard error where the fit gave one.
void print_final_model(const est::ModelParams& p) {
  const auto& se = p.identification.std_errors;
  const auto row = [&](const std::string& path, double value, const char* unit) {
    const auto e = se.find(path);
    if (e != se.end())
      std::printf("    %-22s %12.6g ± %-10.3g %s\n", path.c_str(), value, e->second, unit);
    else
      std::printf("    %-22s %12.6g %-12s %s\n", path.c_str(), value, "(no s.e.)", unit);
  };
  const auto vector = [&](const std::string& block, const auto& v, const char* unit, bool skip_zero) {
    if (skip_zero && v.isZero()) return;
    for (int i = 0; i < static_cast<int>(v.size()); ++i) row("full." + block + "." + std::to_string(i), v[i], unit);
  };
  const est::FullModelParams& f = p.full;
  std::printf("final model (as PARAMS.json holds it):\n  the vehicle's calibration:\n");
  vector("lever_arm", f.lever_arm, "m", false);
  vector("mounting", f.mounting, "rad", false);
  vector("drag_linear", f.drag_linear, "1/s", false);
  vector("drag_quadratic", f.drag_quadratic, "1/m", false);
  vector("accel_scale", f.accel_scale, "", true);
  if (!f.accel_cross.isZero()) {
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        if (i != j) row("full.accel_cross." + std::to_string(i) + std::to_string(j), f.accel_cross(i, j), "");
  }
  if (f.time_offset != 0.0) row("full.time_offset", f.time_offset, "s");
  if (p.identification.process_noise > 0.0)
    std::printf("    %-22s %12.6g %-12s %s\n", "process_noise", p.identification.process_noise, "", "m/s^2/sqrt(Hz)");
  const std::string conditions = est::describe_conditions(f);
  std::printf(p.conditions_flight.starts_with("flights:")
                  ? "  the conditions fitted over these flights (%s), flown on none: %s\n"
                  : "  the conditions of this flight (%s), left behind on any other: %s\n",
              p.conditions_flight.c_str(), conditions.empty() ? "none" : conditions.c_str());
  vector("wind", f.wind, "m/s", true);
  vector("accel_bias", f.accel_bias, "m/s^2", true);
  vector("gyro_bias", f.gyro_bias, "rad/s", true);
}

void print_fit_flags(const dg::ModelFit& fit) {
  for (const std::string& b : fit.at_bounds) std::printf("  warning: %s\n", b.c_str());
  for (const std::string& i : fit.implausible) std::printf("  warning: implausible: %s\n", i.c_str());
}

void print_velocity(const dg::ModelFit& fit) {
  if (!fit.velocity) return;
  print_velocity_scores(*fit.velocity);
}

void print_summary(const dg::Diagnosis& d) {
  for (const std::string& w : d.warnings) std::printf("warning: %s\n", w.c_str());
  if (!d.imu_axes.empty()) std::printf("%s\n", d.imu_axes.c_str());
  std::printf("diagnosed %s: %s model, axes", d.session.c_str(), d.model.c_str());
  for (const std::string& a : d.axes) std::printf(" %s", a.c_str());
  std::printf(", velocity %s; train %.3f:%.3f s, validate %.3f:%.3f s\n", d.velocity_source.c_str(), d.train_start,
              d.train_end, d.validate_start, d.validate_end);
  if (d.gyro_train) {
    const dg::GyroAgainstReference& g = *d.gyro_train;
    std::printf(
        "gyro against the reference's attitude (training window, %zu spans): bias (%.4f, %.4f, %.4f) +- (%.4f, "
        "%.4f, %.4f) rad/s, p = %.3g%s\n",
        g.spans, g.bias.x(), g.bias.y(), g.bias.z(), g.std_error.x(), g.std_error.y(), g.std_error.z(), g.p_value,
        d.gyro_validation ? "" : " (the validation window too short to test it)");
  }
  std::printf("base: RMSE train %.4f, validation %.4f m/s^2\n", d.base.rmse_train, d.base.rmse_validation);
  print_params(d.base.base_params, d.base.std_error_failure);
  print_velocity(d.base);
  print_fit_flags(d.base);
  for (std::size_t i = 0; i < d.steps.size(); ++i) {
    const dg::Step& s = d.steps[i];
    std::printf("step %zu: + %s: RMSE train %.4f -> %.4f, validation %.4f -> %.4f m/s^2\n", i + 1,
                dg::with_needed(s.effect, s.with).c_str(), s.rmse_train_before, s.fit.rmse_train,
                s.rmse_validation_before, s.fit.rmse_validation);
    for (const dg::CandidateTrial& c : s.candidates) {
      if (c.effect == s.effect && !c.held.empty()) std::printf("  with %s\n", c.held.c_str());
      if (c.effect == s.effect && !c.admitted_by.empty()) std::printf("  added by %s\n", c.admitted_by.c_str());
    }
    if (!s.released.empty()) std::printf("  then %s\n", s.released.c_str());
    print_params(s.params, s.fit.std_error_failure);
    print_velocity(s.fit);
    print_fit_flags(s.fit);
  }
  if (!d.last_candidates.empty()) {
    const dg::CandidateTrial& best = d.last_candidates.front();
    if (best.skipped.empty() && !best.rejected_by.empty())
      std::printf("stopped: the best candidate, %s (validation %.4f m/s^2), fails the %s\n", best.effect.c_str(),
                  best.rmse_validation, best.rejected_by.c_str());
    else if (!best.skipped.empty())
      std::printf("stopped: no candidate could be tried (%s: %s)\n", best.effect.c_str(), best.skipped.c_str());
    for (const dg::CandidateTrial& c : d.last_candidates) {
      if (c.skipped.rfind("implausible", 0) == 0 || c.skipped.rfind("undetermined", 0) == 0)
        std::printf("  refused %s: %s\n", c.effect.c_str(), c.skipped.c_str());
      else if (c.rejected_by.rfind("velocity rule", 0) == 0 || c.rejected_by.rfind("likelihood rule", 0) == 0)
        std::printf("  refused %s: %s\n", c.effect.c_str(), c.rejected_by.c_str());
    }
  } else if (!d.steps.empty()) {
    std::printf("stopped: the step limit (--max-steps) was reached\n");
  }
  print_final_model(d.final_params);
  std::printf("summary: %s\n", dg::summary_line(d).c_str());
  std::printf("final residual %s\n", d.residual_white ? "white" : "NOT white");
  for (const dg::Unexplained& u : d.unexplained)
    std::printf("  unexplained (%s, axis %s): %s\n", u.kind.c_str(), u.axis.c_str(), u.where.c_str());
}

// The search's options from the command line, checked.
dg::DiagnoseOptions search_options(const DiagnoseCliOptions& o) {
  dg::DiagnoseOptions options;
  options.model = parse_model(o.model);
  options.axes = parse_axes(o.axis);
  if (o.velocity) options.velocity = parse_velocity(*o.velocity);
  options.limits = plausibility_limits(o.limits);
  for (const std::string& band : o.ignore_bands) options.ignore_bands.push_back(parse_band(band));
  if (o.max_steps < 0) throw std::invalid_argument("--max-steps must be 0 or more");
  options.max_steps = o.max_steps;
  if (o.judge_by_flight && o.residual_only)
    throw std::invalid_argument("--judge-by-flight and --residual-only contradict each other: give one");
  options.choose_by_flight = o.judge_by_flight;
  options.flight_rules = !o.residual_only;
  if (o.lowpass_hz < 0.0) throw std::invalid_argument("--lowpass must be a positive frequency in Hz (0: off)");
  options.lowpass_hz = o.lowpass_hz;
  return options;
}

// What is diagnosed: one session, or several flights joined (cli/commands/flight_set_reading.hpp).
struct DiagnosedData {
  std::optional<replay::SessionSeries> session;
  std::optional<FlightSetReading> flights;
  std::optional<JoinedFlights> joined;
};

// Reads the sessions, and completes `options` by them: the velocity source when none was given, the windows, the
// name of what is diagnosed.
DiagnosedData read_data(const store::Store& store, const DiagnoseCliOptions& o,
                        const std::vector<std::int64_t>& fit_ids, const std::vector<std::int64_t>& validate_ids,
                        bool several, dg::DiagnoseOptions& options) {
  // The reference when the session has one, unless told otherwise. The filter's fit never reads it; a reference
  // read beside it only scores the velocity in the report.
  using replay::ReferenceUse;
  const ReferenceUse reference = !o.velocity                                          ? ReferenceUse::when_present
                                 : *options.velocity == dg::VelocitySource::reference ? ReferenceUse::required
                                 : *options.velocity == dg::VelocitySource::filter    ? ReferenceUse::when_present
                                                                                      : ReferenceUse::none;
  replay::SessionSeriesOptions reading{.link = o.link, .reference = reference, .imu_axes = o.imu_axes};
  set_reference_delay(reading, o.reference_delay);
  DiagnosedData data;
  if (several) {
    data.flights = read_flight_set(store, fit_ids, validate_ids, reading, o.windows);
    if (!options.velocity)
      options.velocity = data.flights->every_reference ? dg::VelocitySource::reference : dg::VelocitySource::filter;
    data.joined = join(*data.flights, *options.velocity == dg::VelocitySource::filter);
    options.train = data.joined->train;
    options.validate = data.joined->validate;
    options.validation_on_other_flights = true;
    options.session = o.db + "#" + o.sessions + (o.validate_sessions ? "/" + *o.validate_sessions : "");
  } else {
    data.session = replay::read_session_series(store, fit_ids.front(), reading);
    if (!options.velocity)
      options.velocity = data.session->series.reference ? dg::VelocitySource::reference : dg::VelocitySource::filter;
    std::tie(options.train, options.validate) = o.windows.resolve(*data.session);
    options.session = o.db + "#" + std::to_string(fit_ids.front());
  }
  return data;
}

// What the reading knew into the diagnosis, and said before the summary.
void add_reading(const DiagnosedData& data, dg::Diagnosis& diagnosis) {
  if (data.flights) {
    // Conditions fitted over several flights are no one flight's: named by the set, they fly on none.
    diagnosis.final_params.conditions_flight = data.flights->identity;
    measure_transfer(*data.flights, diagnosis.final_params, stdout);
  } else {
    const replay::SessionSeries& session = *data.session;
    diagnosis.imu_axes = session.axes.description;
    diagnosis.warnings.insert(diagnosis.warnings.begin(), session.warnings.begin(), session.warnings.end());
    diagnosis.final_params.identification.reference_delay = recorded_reference_delay(session);
    diagnosis.final_params.conditions_flight = session.flight;  // as replay and evaluate will read it
    print_reference_delay(session);  // with the summary: an error before it stays one line
  }
}

// --report's files and --out's model.
void write_outputs(const DiagnoseCliOptions& o, const dg::Diagnosis& diagnosis) {
  if (o.report) {
    const std::filesystem::path dir(*o.report);
    std::filesystem::create_directories(dir);
    dg::write_report_json(diagnosis, dir / "report.json");
    dg::write_report_html(diagnosis, dir);
    std::printf("wrote %s/report.json and %s/report.html\n", o.report->c_str(), o.report->c_str());
  }
  if (o.out) {
    est::save_params(*o.out, diagnosis.final_params);
    // Read back as run, replay and evaluate will: a model they would refuse is said so now, not at take-off.
    try {
      (void)est::load_params(*o.out);
      std::printf("wrote %s: the final model, as run, replay and evaluate estimate with it\n", o.out->c_str());
    } catch (const std::exception& e) {
      std::printf("warning: wrote %s, but the live estimator refuses it: %s\n", o.out->c_str(), e.what());
    }
  }
}

int run(const DiagnoseCliOptions& o) {
  dg::DiagnoseOptions options = search_options(o);
  const std::vector<std::int64_t> fit_ids = parse_session_list(o.sessions);
  std::vector<std::int64_t> validate_ids;
  if (o.validate_sessions) validate_ids = parse_session_list(*o.validate_sessions);
  const bool several = fit_ids.size() > 1 || !validate_ids.empty();
  if (several && options.velocity == dg::VelocitySource::eq12)
    throw std::invalid_argument(
        "--velocity imu takes one session: its open-loop integral would run from one flight into the next");

  const store::Store store(o.db, {.read_only = true});
  const DiagnosedData data = read_data(store, o, fit_ids, validate_ids, several, options);
  // Progress on a terminal only: a log file or a pipe gets the summary alone.
  const bool show_progress = isatty(STDERR_FILENO) == 1;
  if (show_progress)
    options.progress = [progress = std::make_shared<TerminalProgress>()](const auto& p) { (*progress)(p); };
  dg::Diagnosis diagnosis = dg::run_diagnosis(several ? data.joined->set.series : data.session->series, options);
  if (show_progress) TerminalProgress::clear();
  add_reading(data, diagnosis);
  print_summary(diagnosis);
  if (several) print_flight_map(stdout, *data.flights, *data.joined);
  write_outputs(o, diagnosis);
  return 0;
}

const RegisterCommand kDiagnose([](CLI::App& app) -> CommandRunner {
  auto o = std::make_shared<DiagnoseCliOptions>();
  auto* cmd = app.add_subcommand("diagnose",
                                 "Find what the accelerometer model misses: fit it, analyse the residual, add effects");
  cmd->add_option("--db", o->db, "Session store (SQLite), opened read-only")->required();
  add_flight_set_options(*cmd, o->sessions, o->validate_sessions, "diagnosed together");
  cmd->add_option("--link", o->link, "Link id (default: the session's link with the most samples)");
  cmd->add_option("--imu-axes", o->imu_axes,
                  "The IMU's axes: auto (from gravity), frd, flu, x-up, R:..., q:... (default: as the session "
                  "recorded, else auto; docs/estimator.md, IMU axes)");
  cmd->add_option("--axis", o->axis, "x | y | both")->capture_default_str();
  cmd->add_option("--model", o->model, "Base model: paper (eq. 14 per axis) | full (3-D rigid body and mounting)")
      ->capture_default_str();
  cmd->add_option("--velocity", o->velocity,
                  "reference | filter (IMU only: the drag-velocity filter's prediction, fitted by the filter "
                  "error method) | imu (eq. 12's open-loop integral; drifts); default: reference when the session "
                  "has one, else filter");
  add_window_options(*cmd, o->windows);
  add_reference_delay_option(*cmd, o->reference_delay);
  cmd->add_option("--ignore-band", o->ignore_bands, "F0:F1 in Hz the frequency search ignores, repeatable");
  cmd->add_option("--max-steps", o->max_steps, "Effects added at most")->capture_default_str();
  cmd->add_flag("--judge-by-flight", o->judge_by_flight,
                "Of the candidates that pass every rule, take one that flies best (validation velocity with the "
                "reference, the filter's likelihood from the IMU alone) instead of the lowest residual. Without it a "
                "step is still refused when it flies worse or its parameters are undetermined (docs/effects.md)");
  cmd->add_flag("--residual-only", o->residual_only,
                "Judge steps by the specific-force residual alone, as the paper does: no velocity or likelihood "
                "rule, no refusal of undetermined parameters. For comparison; a step it keeps may fly worse");
  cmd->add_option("--lowpass", o->lowpass_hz,
                  "Compare model and measurement below this frequency only, Hz (0: off); for airframes whose "
                  "vibration swamps the accelerometers")
      ->capture_default_str();
  cmd->add_option("--report", o->report, "Directory for report.json and report.html (created if needed)");
  cmd->add_option("--out", o->out,
                  "Write the final model (base plus every effect added, with standard errors) as PARAMS.json for "
                  "run, replay and evaluate");
  add_limit_option(*cmd, o->limits);
  return [o] { return run(*o); };
});

}  // namespace
}  // namespace imubridge::cli
