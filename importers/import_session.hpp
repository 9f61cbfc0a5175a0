#pragma once
// The shape every importer has, in one place: a session of kind "import" with its one link begun, the link's bytes
// fed through the session engine without estimation (an import has no parameters: a replay estimates), the log's own
// events and the import's problems stored, the holes in the IMU's data and its declared axes checked, the session
// ended. The importers differ only in how they read their files and what they say of them. docs/replay.md.
#include <cstdint>
#include <optional>
#include <span>
#include <string>

#include "estimator/imu_axes.hpp"
#include "importers/import_problem.hpp"
#include "importers/log_import.hpp"
#include "pipeline/link_recorder.hpp"
#include "pipeline/recorded_session.hpp"
#include "pipeline/session_config.hpp"
#include "pipeline/session_engine.hpp"
#include "store/store.hpp"

namespace imubridge::importers {

// Where an event is stored: on the link or (nothing) the whole session, at the session's clock and the wall clock.
struct EventAt {
  std::optional<std::int64_t> link{};
  std::int64_t mono_ns = 0, wall_ns = 0;
};

// What the end of an import found in its samples.
struct ImportChecks {
  Gaps gaps;                       // holes in the IMU's data
  estimator::AxesResolution axes;  // the declared axes checked against gravity
};

class ImportSession {
 public:
  // Begins the session and its link (pipeline::begin_recorded_session). `on_problem` may be empty.
  ImportSession(store::Store& store, const pipeline::SessionStart& start, const pipeline::SessionLink& link,
                ProblemCallback on_problem);
  ImportSession(const ImportSession&) = delete;
  ImportSession& operator=(const ImportSession&) = delete;

  std::int64_t id() const { return id_; }
  std::int64_t link() const { return link_; }
  const pipeline::LinkRecorder& recorder() const { return recording_.link(0); }
  // After the recording, which is the engine's first sink.
  void add_sink(pipeline::SessionSink& sink) { engine_.add_sink(sink); }

  // One chunk of the link's bytes, as received at these times; the store commits when due.
  void feed(std::span<const std::uint8_t> bytes, std::int64_t mono_ns, std::int64_t wall_ns);
  // After the last chunk: the link's decoder flushed, the engine finished.
  void finish_link(std::int64_t mono_ns, std::int64_t wall_ns);

  // An event of the log's own (a logged string, a mode change): `kind`, one, at `at`.
  void log_event(const EventAt& at, std::string kind, std::string detail);
  // The problem to the callback, and stored at `at` as an event of kind import_<kind>, its count the problem's, its
  // detail the importer's words (each format says where in its own terms).
  void report(const ImportProblem& problem, const EventAt& at, std::string detail);
  // The latest time an event was stored at, for importers whose session ends with its last event.
  std::int64_t latest_event_ns() const { return latest_event_ns_; }

  // The holes over `gap_threshold_s` in `samples` as gap events (their spans counted from `start_ns`), the declared
  // axes checked against the samples' gravity (a contradiction an imu_axes_mismatch event at `last`), and the
  // session ended at `end_ns`.
  ImportChecks end(const ImportedSamples& samples, double gap_threshold_s, std::int64_t start_ns,
                   const estimator::ImuAxes& declared, const EventAt& last, std::int64_t end_ns);

 private:
  void store_event(const EventAt& at, std::string kind, std::int64_t count, std::string detail);

  ImportSession(store::Store& store, const pipeline::SessionLink& link, pipeline::RecordedSession recorded,
                ProblemCallback on_problem);

  store::Store& store_;
  std::int64_t id_ = 0, link_ = 0;
  pipeline::SessionEngine engine_{nullptr};
  pipeline::SessionRecording recording_;
  ProblemCallback on_problem_;
  std::int64_t latest_event_ns_ = 0;
};

}  // namespace imubridge::importers
