// `imubridge identify`: fit the accelerometer model to a recorded session and write PARAMS.json
// (docs/identification.md). A short summary for people goes to stderr.
#include "identification/identify.hpp"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
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
#include "diagnose/filter_identification.hpp"
#include "estimator/constants.hpp"
#include "estimator/params.hpp"
#include "fileio/whole_file.hpp"
#include "identification/plausibility.hpp"
#include "identification/velocity_scores.hpp"
#include "replay/session_series.hpp"
#include "store/store.hpp"

namespace imubridge::cli {
namespace {

namespace est = imubridge::estimator;
namespace fs = std::filesystem;

struct IdentifyCliOptions {
  std::string db, out, sessions;
  std::optional<std::string> validate_sessions;
  std::optional<std::int64_t> link;
  std::optional<std::string> imu_axes;
  std::optional<double> reference_delay;
  std::string model = "paper", method = "lm";
  std::optional<std::string> velocity;  // default: the reference when the session has one, else the filter
  WindowArgs windows;
  std::vector<std::string> hold, limits;
  est::GaOptions ga;
};

// How a parameter is shown to people: degrees for angles, its SI unit otherwise.
struct Shown {
  double scale;
  const char* unit;
};
Shown shown(const std::string& name) {
  if (name == "beta" || name == "alpha" || name.starts_with("mounting")) return {180.0 / est::kPi, "deg"};
  if (name == "r" || name.starts_with("lever_arm")) return {1.0, "m"};
  if (name == "mu" || name.starts_with("drag_quadratic")) return {1.0, "1/m"};
  if (name == "process_noise_log10") return {1.0, "log10(m/s^2/sqrt(Hz))"};
  if (name.starts_with("drag_linear")) return {1.0, "1/s"};
  return {1.0, "m/s^2"};  // accel_bias
}

// The lower triangle, then a warning for every pair the data cannot tell apart.
void print_correlation(const est::Uncertainty& u) {
  constexpr double kIndistinct = 0.99;
  const auto at = [&u](std::size_t i, std::size_t j) {
    return u.correlation(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j));
  };
  std::fprintf(stderr, "  correlation:\n");
  for (std::size_t i = 0; i < u.names.size(); ++i) {
    std::fprintf(stderr, "    %-16s", u.names[i].c_str());
    for (std::size_t j = 0; j <= i; ++j) std::fprintf(stderr, " %6.3f", at(i, j));
    std::fprintf(stderr, "\n");
  }
  for (std::size_t i = 0; i < u.names.size(); ++i) {
    for (std::size_t j = 0; j < i; ++j) {
      if (std::abs(at(i, j)) > kIndistinct)
        std::fprintf(stderr, "  warning: %s and %s are correlated %.3f: these data cannot tell them apart\n",
                     u.names[j].c_str(), u.names[i].c_str(), at(i, j));
    }
  }
}

// `source`: what the model was fitted on, "session 3 (link 3)" or the flights of a set.
// `written`: whether PARAMS.json was saved (a refused fit is not, and its summary must not say otherwise).
void print_summary(const IdentifyCliOptions& o, const est::IdentifyResult& result, est::VelocitySource velocity,
                   const std::string& source, double wall_seconds, bool written) {
  const est::Identification& id = result.params.identification;
  std::fprintf(stderr, "identified the %s model by %s from %s, velocity %s\n", o.model.c_str(), id.method.c_str(),
               source.c_str(), std::string(est::name(velocity)).c_str());
  for (const est::FitReport& fit : result.fits) {
    std::fprintf(stderr, "%s: train %.3f:%.3f s (%zu samples), validate %.3f:%.3f s (%zu samples)\n", fit.name.c_str(),
                 id.fit_windows[0].start, id.fit_windows[0].end, fit.fit_samples, id.validation_windows[0].start,
                 id.validation_windows[0].end, fit.validation_samples);
    const est::Uncertainty& u = fit.uncertainty;
    for (std::size_t i = 0; i < u.names.size(); ++i) {
      const Shown s = shown(u.names[i]);
      const double value = u.value[static_cast<Eigen::Index>(i)] * s.scale;
      if (u.failure.empty())
        std::fprintf(stderr, "  %-16s %12.6g ± %-10.3g %s\n", u.names[i].c_str(), value,
                     u.std_error[static_cast<Eigen::Index>(i)] * s.scale, s.unit);
      else
        std::fprintf(stderr, "  %-16s %12.6g %s\n", u.names[i].c_str(), value, s.unit);
    }
    if (!u.failure.empty()) std::fprintf(stderr, "  no standard errors: %s\n", u.failure.c_str());
    const auto rmse = [&](const std::string& key) { return id.rmse.at(key); };
    if (fit.name == "full") {
      std::fprintf(stderr, "  RMSE x/y: fit %.4f/%.4f, validation %.4f/%.4f m/s^2\n", rmse("full.x.fit"),
                   rmse("full.y.fit"), rmse("full.x.validation"), rmse("full.y.validation"));
    } else {
      std::fprintf(stderr, "  RMSE fit %.4f, validation %.4f m/s^2\n", rmse(fit.name + ".fit"),
                   rmse(fit.name + ".validation"));
    }
    std::fprintf(stderr, "  OF %.4f m/s^2 on the training window; solved in %.3f s", fit.fit_objective,
                 fit.solve_seconds);
    if (fit.lm) {
      std::fprintf(stderr, " (LM: %d iterations, %s)", fit.lm->iterations,
                   fit.lm->converged ? "converged" : fit.lm->message.c_str());
    }
    std::fprintf(stderr, "\n");
    if (fit.lm && u.failure.empty()) print_correlation(u);
  }
  if (id.process_noise > 0.0)
    std::fprintf(stderr, "the filter's process noise, fitted with the model: %.4g m/s^2/sqrt(Hz)\n", id.process_noise);
  if (written)
    std::fprintf(stderr, "wall time %.3f s; wrote %s\n", wall_seconds, o.out.c_str());
  else
    std::fprintf(stderr, "wall time %.3f s\n", wall_seconds);
}

// The GA's convergence curves (the paper's Fig. 12): one row per generation, one column per fitted group.
void write_convergence(const fs::path& path, const std::vector<est::FitReport>& fits) {
  std::string csv = "generation";
  for (const est::FitReport& fit : fits) csv += "," + fit.name;
  csv += "\n";
  for (std::size_t g = 0; g < fits.front().convergence.size(); ++g) {
    csv += std::to_string(g);
    for (const est::FitReport& fit : fits) {
      char cell[32];
      std::snprintf(cell, sizeof cell, ",%.9g", fit.convergence[g]);
      csv += cell;
    }
    csv += "\n";
  }
  fileio::write_whole_file(path, csv);
}

est::FullHold parse_hold(const std::vector<std::string>& names) {
  const auto& blocks = est::kFullBlockNames;
  est::FullHold hold;
  for (const std::string& name : names) {
    const auto it = std::find(blocks.begin(), blocks.end(), name);
    if (it == blocks.end())
      throw std::invalid_argument(
          "unknown block \"" + name +
          "\" for --hold (valid: lever_arm, mounting, drag_linear, drag_quadratic, accel_bias)");
    hold.blocks[static_cast<std::size_t>(it - blocks.begin())] = true;
  }
  return hold;
}

est::IdentifyOptions identify_options(const IdentifyCliOptions& o) {
  est::IdentifyOptions options;
  options.model = est::parse_model(o.model);
  options.method = est::parse_method(o.method);
  if (o.velocity) options.velocity = est::parse_velocity(*o.velocity);
  options.ga = o.ga;
  options.hold = parse_hold(o.hold);
  if (!o.hold.empty() && options.model != est::ModelKind::full)
    throw std::invalid_argument("--hold applies to --model full only");
  return options;
}

replay::SessionSeriesOptions reading_options(const IdentifyCliOptions& o, const est::IdentifyOptions& options) {
  replay::SessionSeriesOptions reading{.link = o.link,
                                         // Read when present in any case: the velocity the model gives is scored
                                         // against it (the filter's and eq. (12)'s fits never read it).
                                         .reference = o.velocity && options.velocity == est::VelocitySource::reference
                                                          ? replay::ReferenceUse::required
                                                          : replay::ReferenceUse::when_present,
                                         .imu_axes = o.imu_axes};
  set_reference_delay(reading, o.reference_delay);
  return reading;
}

// The velocity source when none was given (the reference when the data have one), and the GA refused where the
// filter fits.
void choose_velocity(const IdentifyCliOptions& o, est::IdentifyOptions& options, bool has_reference) {
  if (!o.velocity) options.velocity = has_reference ? est::VelocitySource::reference : est::VelocitySource::filter;
  if (options.velocity == est::VelocitySource::filter && options.method != est::Method::lm)
    throw std::invalid_argument(
        o.velocity ? "--velocity filter fits by LM only (the GA would run the filter for every individual)"
                   : "no reference, so the velocity is the filter's, which fits by LM only (the GA would "
                     "run the filter for every individual); --velocity eq12 runs the paper's GA on the IMU alone");
}

// Writes PARAMS.json (and the GA's curve) when the fit is plausible; else prints why not. Returns the exit status.
int write_or_refuse(const IdentifyCliOptions& o, const est::IdentifyResult& result,
                    const std::vector<est::Implausibility>& implausible) {
  for (const std::string& line : est::negligible_drag(result.params.full)) std::printf("warning: %s\n", line.c_str());
  if (!implausible.empty()) {
    for (const est::Implausibility& i : implausible) std::printf("refused: implausible: %s\n", i.message.c_str());
    std::fprintf(stderr,
                 "identify: the fit is refused and %s is not written: no airframe has these values (a window without "
                 "the manoeuvres that determine them, or wrong --imu-axes, are the usual causes)\n",
                 o.out.c_str());
    return 1;
  }
  return 0;
}

// A fit and the plausibility limits it exceeds. When the only one is the accelerometer's bias, and the bias was fitted:
// on a steady flight a bias and the mounting's tilt read alike (a constant force either way), and the fit can walk
// their valley to where no accelerometer's offset is. The calibration is then fitted again with the bias held at
// zero, the mounting carrying the flight's offset, and `bias_held` says so, instead of refusing a vehicle whose other
// values are plausible (docs/identification.md, "Plausibility").
struct CheckedFit {
  est::IdentifyResult result;
  std::vector<est::Implausibility> implausible;
  std::optional<std::string> bias_held;
};

CheckedFit fit_checked(const est::ImuSeries& series, est::IdentifyOptions options,
                       const est::PlausibilityLimits& limits) {
  const auto fit = [&] {
    return options.velocity == est::VelocitySource::filter ? diagnose::identify_by_filter_error(series, options)
                                                           : est::identify(series, options);
  };
  CheckedFit out{fit(), {}, std::nullopt};
  out.implausible = est::check_plausibility(out.result.params.full, limits);
  const bool only_the_bias =
      !out.implausible.empty() && std::all_of(out.implausible.begin(), out.implausible.end(),
                                              [](const est::Implausibility& i) { return i.limit == "accel_bias"; });
  if (options.model != est::ModelKind::full || options.hold.held(est::FullBlock::accel_bias) || !only_the_bias)
    return out;
  const std::string was = out.implausible.front().message;
  options.hold.blocks[static_cast<int>(est::FullBlock::accel_bias)] = true;
  out.result = fit();
  out.implausible = est::check_plausibility(out.result.params.full, limits);
  out.bias_held = "the fitted accelerometer bias was implausible (" + was +
                  "): on a steady flight a bias reads like the mounting's tilt or a drag, so the model was fitted "
                  "again with the bias held at zero (as --hold accel_bias), and the mounting carries the offset of "
                  "the flights it was fitted on";
  return out;
}

void save(const IdentifyCliOptions& o, const est::IdentifyResult& result) {
  est::save_params(o.out, result.params);
  if (!result.fits.front().convergence.empty()) {
    const fs::path curve = fs::path(o.out).replace_extension(".convergence.csv");
    write_convergence(curve, result.fits);
  }
}

// Several flights (--session A,B,C, --validate-session D,E; cli/commands/flight_set_reading.hpp), fitted on the
// first ones and validated on the others. The conditions (biases, wind) fitted over several flights are no one
// flight's: PARAMS.json names the set, so they fly on none.
int run_over_flights(const IdentifyCliOptions& o, const std::vector<std::int64_t>& fit_ids,
                     const std::vector<std::int64_t>& validate_ids) {
  const auto start = std::chrono::steady_clock::now();
  est::IdentifyOptions options = identify_options(o);
  if (o.velocity && options.velocity == est::VelocitySource::eq12)
    throw std::invalid_argument(
        "--velocity eq12 takes one session: its open-loop integral would run from one flight into the next");
  const est::PlausibilityLimits limits = plausibility_limits(o.limits);
  const store::Store store(o.db, {.read_only = true});
  const FlightSetReading flights =
      read_flight_set(store, fit_ids, validate_ids, reading_options(o, options), o.windows);
  choose_velocity(o, options, flights.every_reference);
  const JoinedFlights joined = join(flights, options.velocity == est::VelocitySource::filter);
  options.train = joined.train;
  options.validate = joined.validate;
  CheckedFit checked = fit_checked(joined.set.series, options, limits);
  est::IdentifyResult& result = checked.result;
  const std::vector<est::Implausibility>& implausible = checked.implausible;
  result.params.conditions_flight = flights.identity;
  if (implausible.empty()) {
    measure_transfer(flights, result.params, stderr);
    save(o, result);
  }

  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  print_summary(o, result, options.velocity, describe_sessions(flights), wall, implausible.empty());
  print_flight_map(stderr, flights, joined);
  if (checked.bias_held) std::printf("warning: %s\n", checked.bias_held->c_str());
  const int status = write_or_refuse(o, result, implausible);
  if (status == 0) {
    std::string listed;
    for (const std::int64_t id : validate_ids) listed += (listed.empty() ? "" : ",") + std::to_string(id);
    std::fprintf(stderr,
                 "the velocity on each validating flight: imubridge evaluate --db %s --session %s --params %s\n",
                 o.db.c_str(), listed.c_str(), o.out.c_str());
  }
  return status;
}

int run(const IdentifyCliOptions& o) {
  const std::vector<std::int64_t> fit_ids = parse_session_list(o.sessions);
  std::vector<std::int64_t> validate_ids;
  if (o.validate_sessions) validate_ids = parse_session_list(*o.validate_sessions);
  if (fit_ids.size() > 1 || !validate_ids.empty()) return run_over_flights(o, fit_ids, validate_ids);
  const std::int64_t session_id = fit_ids.front();
  const auto start = std::chrono::steady_clock::now();
  est::IdentifyOptions options = identify_options(o);
  const est::PlausibilityLimits limits = plausibility_limits(o.limits);

  const store::Store store(o.db, {.read_only = true});
  const replay::SessionSeries session = replay::read_session_series(store, session_id, reading_options(o, options));
  for (const std::string& w : session.warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
  choose_velocity(o, options, session.series.reference.has_value());
  std::tie(options.train, options.validate) = o.windows.resolve(session);
  CheckedFit checked = fit_checked(session.series, options, limits);
  est::IdentifyResult& result = checked.result;
  result.params.identification.reference_delay = recorded_reference_delay(session);
  result.params.conditions_flight = session.flight;  // as replay and evaluate will read it

  // Refused, not warned about: a model no airframe has flies worse than none (docs/identification.md, "Plausibility").
  const std::vector<est::Implausibility>& implausible = checked.implausible;
  if (implausible.empty()) save(o, result);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::fprintf(stderr, "%s\n", session.axes.description.c_str());
  print_reference_delay(session);  // with the summary: an error before it stays one line
  print_summary(o, result, options.velocity,
                "session " + std::to_string(session_id) + " (link " + std::to_string(session.link_id) + ")", wall,
                implausible.empty());
  if (options.velocity == est::VelocitySource::eq12) {
    if (const auto drift = est::eq12_drift_warning(session.series, result.params.full.mounting,
                                                   result.params.identification.fit_windows.front()))
      std::printf("warning: %s\n", drift->c_str());
  }
  // What the identified model does for the velocity, and whether its values are those of a real airframe.
  const est::Identification& id = result.params.identification;
  const est::Windows windows{id.fit_windows.front(), id.validation_windows.front()};
  if (const auto scores = est::score_velocity(session.series, result.params, windows)) {
    const est::VelocityScores zero = est::zero_velocity_scores(session.series, result.params.full.mounting, windows);
    print_velocity_scores(*scores, "");
    std::printf("zero velocity scores train %.3f, validation %.3f m/s (horizontal)\n", zero.train.horizontal,
                zero.validation.horizontal);
  }
  if (checked.bias_held) std::printf("warning: %s\n", checked.bias_held->c_str());
  return write_or_refuse(o, result, implausible);
}

const RegisterCommand kIdentify([](CLI::App& app) -> CommandRunner {
  auto o = std::make_shared<IdentifyCliOptions>();
  auto* cmd = app.add_subcommand("identify", "Fit the accelerometer model to a recorded session; write PARAMS.json");
  cmd->add_option("--db", o->db, "Session store (SQLite), opened read-only")->required();
  add_flight_set_options(*cmd, o->sessions, o->validate_sessions, "fitted together");
  cmd->add_option("--link", o->link, "Link id (default: the session's link with the most samples)");
  cmd->add_option("--imu-axes", o->imu_axes,
                  "The IMU's axes: auto (from gravity), frd, flu, x-up, R:..., q:... (default: as the session "
                  "recorded, else auto; docs/estimator.md, IMU axes)");
  cmd->add_option("--model", o->model, "paper (eq. 14, pitch and roll axes) | full (the 3-D model)")
      ->capture_default_str();
  cmd->add_option("--method", o->method, "ga (the paper's) | lm (Levenberg-Marquardt) | ga+lm")->capture_default_str();
  add_window_options(*cmd, o->windows);
  add_limit_option(*cmd, o->limits);
  add_reference_delay_option(*cmd, o->reference_delay);
  cmd->add_option("--velocity", o->velocity,
                  "Velocity in the drag term: reference | filter (IMU only: the drag-velocity filter running the "
                  "model, fitted by the filter error method) | eq12 (the paper's open-loop integral of the gyro; "
                  "drifts); default: reference when the session has one, else filter");
  cmd->add_option("--hold", o->hold,
                  "Full model: keep a block at its default, repeatable "
                  "(lever_arm, mounting, drag_linear, drag_quadratic, accel_bias)");
  cmd->add_option("--seed", o->ga.seed, "GA: random seed (same seed, same result)")->capture_default_str();
  cmd->add_option("--population", o->ga.population, "GA: individuals per generation")->capture_default_str();
  cmd->add_option("--generations", o->ga.generations, "GA: generations")->capture_default_str();
  cmd->add_option("--mutation", o->ga.mutation, "GA: probability of mutating each gene of a child")
      ->capture_default_str();
  cmd->add_option("--out", o->out, "Where to write PARAMS.json (the GA's curve goes beside it, .convergence.csv)")
      ->required();
  return [o] { return run(*o); };
});

}  // namespace
}  // namespace imubridge::cli
