// `imubridge evaluate`: run the drag-velocity estimator over a session with a reference trajectory and print, as
// JSON, how far its velocity is from the truth, beside the raw drag inversion, eq. (12)'s open-loop integration and
// "not moving" (docs/identification.md).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "cli/command.hpp"
#include "cli/commands/reference_delay_option.hpp"
#include "cli/commands/session_list.hpp"
#include "cli/commands/session_windows.hpp"
#include "diagnose/search.hpp"
#include "estimator/params.hpp"
#include "identification/flight_set.hpp"
#include "identification/identify.hpp"
#include "identification/velocity_scores.hpp"
#include "replay/session_series.hpp"
#include "store/store.hpp"

namespace imubridge::cli {
namespace {

namespace est = imubridge::estimator;
using nlohmann::json;

struct EvaluateCliOptions {
  std::string db, sessions;
  std::optional<std::string> params;
  std::optional<std::int64_t> link;
  std::optional<std::string> imu_axes;
  std::optional<double> reference_delay;
  bool in_flight = false;
  std::optional<std::string> window, baseline_train;
  std::optional<std::string> baseline_sessions;
};

json to_json(const est::VelocityError& e) {
  return {{"x", e.axis.x()}, {"y", e.axis.y()}, {"horizontal", e.horizontal}};
}

replay::SessionSeries read_session(const store::Store& store, std::int64_t id, const EvaluateCliOptions& o) {
  replay::SessionSeriesOptions reading{
      .link = o.link, .reference = replay::ReferenceUse::required, .imu_axes = o.imu_axes};
  set_reference_delay(reading, o.reference_delay);
  replay::SessionSeries session = replay::read_session_series(store, id, reading);
  for (const std::string& w : session.warnings)
    std::fprintf(stderr, "warning: session %lld: %s\n", static_cast<long long>(id), w.c_str());
  return session;
}

// The least-squares anchor and where it was fitted (docs/results.md, "fair anchors").
// A line that cannot be fitted or inverted (no drag in the data) is said in its place, not fatal: zero velocity and
// the model are still scored.
struct AnchorUnfit : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};
template <typename F>
auto anchor_step(F&& step) {
  try {
    return step();
  } catch (const std::invalid_argument& e) {
    throw AnchorUnfit(e.what());
  }
}
struct Anchor {
  est::LeastSquaresDrag fit;
  std::vector<std::int64_t> sessions;
  std::vector<est::TimeWindow> train;  // each session's, in its own time
};
est::TimeWindow anchor_window(const replay::SessionSeries& session, const EvaluateCliOptions& o) {
  const est::TimeWindow span = percent_span(session, o.in_flight).window;
  return o.baseline_train ? est::parse_window(*o.baseline_train, span) : span;
}
Anchor fit_anchor(const replay::SessionSeries& session, std::int64_t id, const EvaluateCliOptions& o) {
  const est::TimeWindow train = anchor_window(session, o);
  return {anchor_step([&] { return est::fit_least_squares_drag(session.series, train); }), {id}, {train}};
}
// Several sessions: one line fitted over their windows together, as a calibration over several flights is
// (identification/flight_set.hpp joins them; the blocks never span two flights).
Anchor fit_anchor(const store::Store& store, const std::vector<std::int64_t>& ids, const EvaluateCliOptions& o) {
  if (ids.size() == 1) return fit_anchor(read_session(store, ids.front(), o), ids.front(), o);
  Anchor out;
  std::vector<est::ImuSeries> flights;
  for (const std::int64_t id : ids) {
    const replay::SessionSeries session = read_session(store, id, o);
    out.train.push_back(est::clip(anchor_window(session, o), session.series.t, "anchor's training"));
    flights.push_back(est::cut(session.series, out.train.back()));
  }
  const est::FlightSet set = est::join_flights(flights);
  out.fit = anchor_step([&] { return est::fit_least_squares_drag(set.series, est::data_span(set.series.t)); });
  out.sessions = ids;
  return out;
}

// One session's scores, as JSON: the estimator's with PARAMS.json (`file`), the anchor's when asked, zero velocity's.
// `anchor_error`: why --baseline-session's anchor could not be fitted ("" when it was, or none was asked).
json evaluate_session(const store::Store& store, std::int64_t id, const std::optional<est::ModelParams>& file,
                      const std::optional<Anchor>& fixed_anchor, const std::string& anchor_error,
                      const EvaluateCliOptions& o) {
  const replay::SessionSeries session = read_session(store, id, o);
  const est::TimeWindow span = percent_span(session, o.in_flight).window;
  const std::optional<est::TimeWindow> window =
      o.window ? std::optional(est::parse_window(*o.window, span)) : std::nullopt;
  json out = {{"session", id}, {"link", session.link_id}, {"reference_delay_s", session.reference_shift_s}};
  est::TimeWindow scored;
  if (file) {
    std::string left;
    const est::ModelParams params = est::for_flight(*file, session.flight, &left);
    if (!left.empty()) std::fprintf(stderr, "session %lld: %s\n", static_cast<long long>(id), left.c_str());
    const est::VelocityEvaluation e =
        est::evaluate_velocity(session.series, params.full, window, est::config_for(params));
    const est::DragVelocityCounters& c = e.counters;
    scored = e.window;
    out["samples"] = e.samples;
    out["rmse_m_s"] = {{"estimator", to_json(e.estimator)},
                       {"raw_inversion", to_json(e.inversion)},
                       {"eq12", to_json(e.eq12)},
                       {"zero", to_json(e.zero)},
                       {"estimator_constant_known", to_json(e.estimator_constant_known)}};
    // The filter's mean error over the window; estimator_constant_known above is its RMSE without it (a bound: it
    // needs the reference).
    out["estimator_mean_error_m_s"] = {e.estimator_mean_error.x(), e.estimator_mean_error.y()};
    // Expected 2 (two axes) when the filter's variance is honest; docs/estimator.md.
    out["estimator_nees"] = e.nees;
    // Whether the estimator flies nearer the reference than "not moving", or further, beyond what one window's
    // correlated errors give by chance: diagnose's velocity test, one-sided each way (docs/identification.md).
    std::vector<double> loss = e.gain_over_zero;
    for (double& g : loss) g = -g;
    out["estimator_versus_zero_p"] = {{"better", diagnose::velocity_gain_test(e.gain_over_zero).p_value},
                                      {"worse", diagnose::velocity_gain_test(loss).p_value}};
    out["estimator_counters"] = {{"samples_in", c.samples_in},
                                 {"estimates_out", c.estimates_out},
                                 {"rejected_non_finite", c.rejected_non_finite},
                                 {"rejected_out_of_range", c.rejected_out_of_range},
                                 {"rejected_time", c.rejected_time},
                                 {"gaps", c.gaps},
                                 {"clock_restarts", c.clock_restarts},
                                 {"landed", c.landed},
                                 {"resets", c.resets}};
  } else {
    // The anchor alone: zero velocity beside it, in the series' axes as the anchor is.
    scored = est::clip(window.value_or(span), session.series.t, "evaluation");
    const est::VelocityScores zero =
        est::zero_velocity_scores(session.series, Eigen::Vector3d::Zero(), {scored, scored});
    out["rmse_m_s"] = {{"zero", to_json(zero.validation)}};
  }
  out["window"] = {scored.start, scored.end};
  out["series_counts"] = {{"samples", session.counts.samples},
                          {"non_finite", session.counts.non_finite},
                          {"time_not_increasing", session.counts.time_not_increasing},
                          {"outside_reference", session.counts.outside_reference}};
  if (o.baseline_train || o.baseline_sessions) {
    // Fitted on its own window (of this flight, or of --baseline-session's), scored on the evaluation window. A line
    // that cannot be fitted or inverted (no drag in it) is said in its place; the rest is still scored.
    try {
      if (!anchor_error.empty()) throw AnchorUnfit(anchor_error);
      const Anchor anchor = fixed_anchor ? *fixed_anchor : fit_anchor(session, id, o);
      const est::LeastSquaresDragScores a =
          anchor_step([&] { return est::score_least_squares_drag(session.series, anchor.fit, scored); });
      out["rmse_m_s"]["least_squares_means"] = to_json(a.raw);
      out["rmse_m_s"]["least_squares_smoothed"] = to_json(a.smoothed);
      json train = json::array();
      for (const est::TimeWindow& w : anchor.train) train.push_back({w.start, w.end});
      out["least_squares"] = {{"train_sessions", anchor.sessions},
                              {"train_windows", train},
                              {"k", {anchor.fit.k.x(), anchor.fit.k.y()}},
                              {"b", {anchor.fit.b.x(), anchor.fit.b.y()}},
                              {"blocks_scored", a.blocks}};
      if (!anchor.fit.note.empty()) out["least_squares"]["note"] = anchor.fit.note;
    } catch (const AnchorUnfit& e) {
      out["least_squares_error"] = e.what();
    }
  }
  print_reference_delay(session);
  return out;
}

double median(std::vector<double> x) {
  if (x.empty()) return std::nan("");
  std::sort(x.begin(), x.end());
  const std::size_t n = x.size();
  return n % 2 == 1 ? x[n / 2] : 0.5 * (x[n / 2 - 1] + x[n / 2]);
}

// A flight's estimator against zero velocity at this one-sided level, each way: per flight, as a user reads one.
constexpr double kVersusZeroLevel = 0.01;
std::string_view versus_zero(const json& p) {
  if (p["better"].get<double>() < kVersusZeroLevel) return "better";
  if (p["worse"].get<double>() < kVersusZeroLevel) return "worse";
  return "-";
}

// Several flights: the per-flight table on stderr, and for each velocity scored (the estimator's, the anchor's) the
// medians and the count of flights worse than zero velocity, which is how a user judges a calibration.
json summarise(const json& flights, std::size_t failed) {
  struct Column {
    const char* source;
    bool estimator;  // the filter's: it has a NEES
    std::vector<double> rmse, ratio;
    std::size_t worse = 0;
    std::size_t clearly_better = 0, clearly_worse = 0;  // the estimator's, by estimator_versus_zero_p
  };
  std::vector<Column> columns{{"estimator", true, {}, {}},
                              {"least_squares_smoothed", false, {}, {}},
                              {"estimator_constant_known", false, {}, {}}};
  std::vector<double> zero, nees;
  std::fprintf(stderr, "%8s %9s %9s %7s %6s %7s %12s %12s\n", "session", "zero", "estimator", "ratio", "nees",
               "vs_zero", "ls_smoothed", "const_known");
  for (const json& f : flights) {
    const long long session = f["session"].get<long long>();
    if (f.contains("error")) {
      std::fprintf(stderr, "%8lld  not scored: %s\n", session, f["error"].get<std::string>().c_str());
      continue;
    }
    const json& rmse = f["rmse_m_s"];
    const double z = rmse["zero"]["horizontal"];
    zero.push_back(z);
    std::fprintf(stderr, "%8lld %9.3f", session, z);
    for (Column& c : columns) {
      if (!rmse.contains(c.source)) {
        std::fprintf(stderr, c.estimator ? " %9s %7s %6s %7s" : " %12s", "-", "-", "-", "-");
        continue;
      }
      const double e = rmse[c.source]["horizontal"];
      c.rmse.push_back(e), c.ratio.push_back(e / z);
      c.worse += e > z ? 1 : 0;
      if (c.estimator) {
        nees.push_back(f["estimator_nees"]);
        const std::string_view versus = versus_zero(f["estimator_versus_zero_p"]);
        c.clearly_better += versus == "better" ? 1 : 0;
        c.clearly_worse += versus == "worse" ? 1 : 0;
        std::fprintf(stderr, " %9.3f %7.2f %6.2f %7s", e, e / z, nees.back(), std::string(versus).c_str());
      } else {
        std::fprintf(stderr, " %12.3f", e);
      }
    }
    std::fprintf(stderr, "\n");
  }
  json summary = {{"flights_scored", zero.size()}, {"flights_not_scored", failed}, {"median_zero_m_s", median(zero)}};
  std::fprintf(stderr, "%zu flights, zero velocity's median %.3f m/s\n", zero.size(), median(zero));
  for (const Column& c : columns) {
    if (c.rmse.empty()) continue;
    summary[c.source] = {{"median_rmse_m_s", median(c.rmse)},
                         {"median_ratio_to_zero", median(c.ratio)},
                         {"flights_worse_than_zero", c.worse}};
    std::fprintf(stderr, "%s: median %.3f m/s (median ratio to zero %.2f), %zu of %zu flights worse than zero",
                 c.source, median(c.rmse), median(c.ratio), c.worse, c.rmse.size());
    if (c.estimator) {
      summary[c.source]["median_nees"] = median(nees);
      summary[c.source]["flights_clearly_better_than_zero"] = c.clearly_better;
      summary[c.source]["flights_clearly_worse_than_zero"] = c.clearly_worse;
      std::fprintf(stderr, ", median NEES %.2f; beyond chance (p < %g): %zu better than zero, %zu worse", median(nees),
                   kVersusZeroLevel, c.clearly_better, c.clearly_worse);
    }
    std::fprintf(stderr, "\n");
  }
  if (failed > 0) std::fprintf(stderr, "%zu flight(s) could not be scored (above)\n", failed);
  return summary;
}

int run(const EvaluateCliOptions& o) {
  const std::vector<std::int64_t> ids = parse_session_list(o.sessions);
  if (!o.params && !o.baseline_train && !o.baseline_sessions)
    throw std::invalid_argument(
        "nothing to score: give --params, or --baseline-train / --baseline-session for the "
        "least-squares anchor alone");
  const store::Store store(o.db, {.read_only = true});
  std::optional<est::ModelParams> file;
  if (o.params) file = est::load_params(*o.params);
  std::optional<Anchor> anchor;
  std::string anchor_error;
  if (o.baseline_sessions) {
    const std::vector<std::int64_t> anchor_ids = parse_session_list(*o.baseline_sessions);
    try {
      anchor = fit_anchor(store, anchor_ids, o);
    } catch (const AnchorUnfit& e) {
      // Said once, and in each flight's report; zero velocity and the model are still scored.
      anchor_error = e.what();
      std::fprintf(stderr, "warning: %s\n", anchor_error.c_str());
    }
  }
  if (ids.size() == 1) {
    std::printf("%s\n", evaluate_session(store, ids.front(), file, anchor, anchor_error, o).dump(2).c_str());
    return 0;
  }
  // Several flights: one that cannot be scored (no reference, a window outside it) is reported in its row and in
  // the exit status, and the others are still scored.
  json flights = json::array();
  std::size_t failed = 0;
  for (const std::int64_t id : ids) {
    try {
      flights.push_back(evaluate_session(store, id, file, anchor, anchor_error, o));
    } catch (const std::exception& e) {
      flights.push_back({{"session", id}, {"error", e.what()}});
      ++failed;
    }
  }
  const json summary = summarise(flights, failed);
  std::printf("%s\n",
              json{{"params", o.params ? json(*o.params) : json(nullptr)}, {"flights", flights}, {"summary", summary}}
                  .dump(2)
                  .c_str());
  return failed == 0 ? 0 : 1;
}

const RegisterCommand kEvaluate([](CLI::App& app) -> CommandRunner {
  auto o = std::make_shared<EvaluateCliOptions>();
  auto* cmd = app.add_subcommand(
      "evaluate", "Score the drag-velocity estimator against a session's reference trajectory (JSON on stdout)");
  cmd->add_option("--db", o->db, "Session store (SQLite), opened read-only")->required();
  cmd->add_option("--session", o->sessions,
                  "Session id, or several (3,5,7 or 2-30): each needs a reference trajectory. With several, a "
                  "per-flight table and the medians go to stderr, {flights, summary} to stdout")
      ->required();
  cmd->add_option("--link", o->link, "Link id (default: the session's link with the most samples)");
  cmd->add_option("--imu-axes", o->imu_axes,
                  "The IMU's axes: auto (from gravity), frd, flu, x-up, R:..., q:... (default: as the session "
                  "recorded, else auto; docs/estimator.md, IMU axes)");
  cmd->add_option("--params", o->params,
                  "PARAMS.json, e.g. from `imubridge identify` (without it, the least-squares anchor alone is scored)");
  cmd->add_option("--baseline-train", o->baseline_train,
                  "Also score the least-squares anchor: a = -k v + b per axis on 0.1-s means (PX4's drag tuning), "
                  "fitted on this window against the reference, inverted raw and 1-s smoothed "
                  "(\"least_squares_means\", \"least_squares_smoothed\")");
  cmd->add_option("--baseline-session", o->baseline_sessions,
                  "Fit the anchor on this session, or on several together (1,16,30), each on --baseline-train or its "
                  "whole span (default: each scored session itself): a calibration carried to other flights, like "
                  "the model's");
  add_in_flight_flag(*cmd, o->in_flight);
  add_reference_delay_option(*cmd, o->reference_delay);
  cmd->add_option("--window", o->window,
                  "Score only T0:T1, seconds from the session start or percent of it (40%:) (default: all)");
  return [o] { return run(*o); };
});

}  // namespace
}  // namespace imubridge::cli
