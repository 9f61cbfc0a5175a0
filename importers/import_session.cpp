#include "importers/import_session.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <utility>

namespace imubridge::importers {

std::string_view problem_kind_name(ProblemKind kind) {
  static constexpr std::array<std::string_view, 3> kNames{"skipped", "clipped", "damaged"};  // ProblemKind's order
  return kNames.at(static_cast<std::size_t>(kind));
}

std::string describe(const ImportProblem& problem) {
  return std::to_string(problem.count) + " " + problem.what + " " + std::string(problem_kind_name(problem.kind)) +
         ": " + problem.why + (problem.where ? " (" + *problem.where + ")" : "");
}

namespace {

// The engine with the import's one link added, for the recording that begins with it.
const pipeline::SessionEngine& with_link(pipeline::SessionEngine& engine, const pipeline::RecordedLink& link) {
  engine.add_link(pipeline::make_decoder(link));
  return engine;
}

}  // namespace

ImportSession::ImportSession(store::Store& store, const pipeline::SessionStart& start,
                             const pipeline::SessionLink& link, ProblemCallback on_problem)
    : ImportSession(store, link, pipeline::begin_recorded_session(store, start, {link}), std::move(on_problem)) {}

ImportSession::ImportSession(store::Store& store, const pipeline::SessionLink& link, pipeline::RecordedSession recorded,
                             ProblemCallback on_problem)
    : store_(store),
      id_(recorded.id),
      link_(recorded.store_links[0]),
      recording_(store, recorded, {link}, with_link(engine_, link.recorded)),
      on_problem_(std::move(on_problem)) {
  engine_.add_sink(recording_);
}

void ImportSession::feed(std::span<const std::uint8_t> bytes, std::int64_t mono_ns, std::int64_t wall_ns) {
  engine_.on_chunk(0, bytes, mono_ns, wall_ns);
  store_.commit_if_due(std::chrono::steady_clock::now());
}

void ImportSession::finish_link(std::int64_t mono_ns, std::int64_t wall_ns) {
  engine_.finish_link(0, mono_ns, wall_ns);
  engine_.finish();
}

void ImportSession::store_event(const EventAt& at, std::string kind, std::int64_t count, std::string detail) {
  store_.append_event(id_, {.link_id = at.link,
                            .mono_ns = at.mono_ns,
                            .wall_ns = at.wall_ns,
                            .kind = std::move(kind),
                            .count = count,
                            .detail = std::move(detail)});
  latest_event_ns_ = std::max(latest_event_ns_, at.mono_ns);
}

void ImportSession::log_event(const EventAt& at, std::string kind, std::string detail) {
  store_event(at, std::move(kind), 1, std::move(detail));
}

void ImportSession::report(const ImportProblem& problem, const EventAt& at, std::string detail) {
  if (on_problem_) on_problem_(problem);
  store_event(at, "import_" + std::string(problem_kind_name(problem.kind)), static_cast<std::int64_t>(problem.count),
              std::move(detail));
}

ImportChecks ImportSession::end(const ImportedSamples& samples, double gap_threshold_s, std::int64_t start_ns,
                                const estimator::ImuAxes& declared, const EventAt& last, std::int64_t end_ns) {
  ImportChecks checks{.gaps = samples.record_gaps(store_, id_, link_, gap_threshold_s, start_ns),
                      .axes = samples.resolve_axes(declared)};
  if (checks.axes.mismatch) store_event(last, "imu_axes_mismatch", 1, *checks.axes.mismatch);
  pipeline::end_recorded_session(store_, id_, end_ns);
  return checks;
}

}  // namespace imubridge::importers
