// `imubridge evaluate`: run the drag-velocity estimator over a session with a reference trajectory and print, as
// JSON, how far its velocity is from the truth, beside the raw drag inversion, eq. (12)'s open-loop integration and
// "not moving" (docs/identification.md).
#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>

#include "daemon/command.hpp"
#include "daemon/commands/reference_delay_option.hpp"
#include "daemon/commands/session_windows.hpp"
#include "estimator/identify.hpp"
#include "estimator/params.hpp"
#include "estimator/velocity_scores.hpp"
#include "pipeline/session_series.hpp"
#include "store/store.hpp"

namespace imubridge::cli {
namespace {

namespace est = imubridge::estimator;
using nlohmann::json;

struct EvaluateCliOptions {
  std::string db, params;
  std::int64_t session = 0;
  std::optional<std::int64_t> link;
  std::optional<std::string> imu_axes;
  std::optional<double> reference_delay;
  bool in_flight = false;
  std::optional<std::string> window, baseline_train;
};

json to_json(const est::VelocityError& e) {
  return {{"x", e.axis.x()}, {"y", e.axis.y()}, {"horizontal", e.horizontal}};
}

int run(const EvaluateCliOptions& o) {
  const store::Store store(o.db, {.read_only = true});
  pipeline::SessionSeriesOptions reading{
      .link = o.link, .reference = pipeline::ReferenceUse::required, .imu_axes = o.imu_axes};
  set_reference_delay(reading, o.reference_delay);
  const pipeline::SessionSeries session = pipeline::read_session_series(store, o.session, reading);
  for (const std::string& w : session.warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
  std::string left;
  const est::ModelParams params =
      est::for_flight(est::load_params(o.params), est::flight_identity(session.series), &left);
  if (!left.empty()) std::fprintf(stderr, "%s\n", left.c_str());
  const est::TimeWindow span = percent_span(session, o.in_flight).window;
  const std::optional<est::TimeWindow> window =
      o.window ? std::optional(est::parse_window(*o.window, span)) : std::nullopt;
  const est::VelocityEvaluation e =
      est::evaluate_velocity(session.series, params.full, window, est::config_for(params));
  const est::DragVelocityCounters& c = e.counters;
  const json out = {{"session", o.session},
                    {"link", session.link_id},
                    {"window", {e.window.start, e.window.end}},
                    {"samples", e.samples},
                    {"reference_delay_s", session.reference_shift_s},
                    {"rmse_m_s",
                     {{"estimator", to_json(e.estimator)},
                      {"raw_inversion", to_json(e.inversion)},
                      {"eq12", to_json(e.eq12)},
                      {"zero", to_json(e.zero)}}},
                    // Expected 2 (two axes) when the filter's variance is honest; docs/estimator.md.
                    {"estimator_nees", e.nees},
                    {"estimator_counters",
                     {{"samples_in", c.samples_in},
                      {"estimates_out", c.estimates_out},
                      {"rejected_non_finite", c.rejected_non_finite},
                      {"rejected_out_of_range", c.rejected_out_of_range},
                      {"rejected_time", c.rejected_time},
                      {"gaps", c.gaps},
                      {"clock_restarts", c.clock_restarts}}},
                    {"series_counts",
                     {{"samples", session.counts.samples},
                      {"non_finite", session.counts.non_finite},
                      {"time_not_increasing", session.counts.time_not_increasing},
                      {"outside_reference", session.counts.outside_reference}}}};
  json report = out;
  if (o.baseline_train) {
    // Trained on its own window, scored on the evaluation window: the same data the model is judged on.
    const est::TimeWindow train = est::parse_window(*o.baseline_train, span);
    const est::LinearDragBaseline b = est::linear_drag_baseline(session.series, {train, e.window});
    report["rmse_m_s"]["linear_least_squares"] = to_json(b.scores.validation);
    report["linear_least_squares"] = {
        {"train_window", {train.start, train.end}}, {"k", {b.k.x(), b.k.y()}}, {"b", {b.b.x(), b.b.y()}}};
  }
  print_reference_delay(session);  // once scored: an error before it stays one line
  std::printf("%s\n", report.dump(2).c_str());
  return 0;
}

const RegisterCommand kEvaluate([](CLI::App& app) -> CommandRunner {
  auto o = std::make_shared<EvaluateCliOptions>();
  auto* cmd = app.add_subcommand(
      "evaluate", "Score the drag-velocity estimator against a session's reference trajectory (JSON on stdout)");
  cmd->add_option("--db", o->db, "Session store (SQLite), opened read-only")->required();
  cmd->add_option("--session", o->session, "Session id (it needs a reference trajectory)")->required();
  cmd->add_option("--link", o->link, "Link id (default: the session's link with the most samples)");
  cmd->add_option("--imu-axes", o->imu_axes,
                  "The IMU's axes: auto (from gravity), frd, flu, x-up, R:..., q:... (default: as the session "
                  "recorded, else auto; docs/estimator.md, IMU axes)");
  cmd->add_option("--params", o->params, "PARAMS.json, e.g. from `imubridge identify`")->required();
  cmd->add_option("--baseline-train", o->baseline_train,
                  "Also score the two-parameter linear least-squares drag fit a = -k v + b per axis (PX4's drag "
                  "tuning), fitted on this window T0:T1 against the reference (\"linear_least_squares\")");
  add_in_flight_flag(*cmd, o->in_flight);
  add_reference_delay_option(*cmd, o->reference_delay);
  cmd->add_option("--window", o->window,
                  "Score only T0:T1, seconds from the session start or percent of it (40%:) (default: all)");
  return [o] { return run(*o); };
});

}  // namespace
}  // namespace imubridge::cli
