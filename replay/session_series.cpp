#include "replay/session_series.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <future>
#include <limits>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "estimator/differentiator.hpp"
#include "pipeline/land_detector.hpp"
#include "pipeline/session_config.hpp"

namespace imubridge::replay {
namespace {

using Eigen::Quaterniond;
using Eigen::Vector3d;

Vector3d vector_of(const std::array<double, 3>& a) { return {a[0], a[1], a[2]}; }

std::string session_name(std::int64_t session) { return "session " + std::to_string(session); }

std::int64_t choose_link(const store::Store& store, std::int64_t session, const std::optional<std::int64_t>& link) {
  const std::vector<store::Link> links = store.links(session);
  if (link) {
    const bool known = std::any_of(links.begin(), links.end(), [&](const store::Link& l) { return l.id == *link; });
    if (!known) throw std::invalid_argument(session_name(session) + " has no link " + std::to_string(*link));
    return *link;
  }
  // One link, as most recordings have: the one with the most samples if it has any, which its first sample tells
  // without a pass over every row.
  if (links.size() == 1) {
    if (store.first_samples(session).empty()) throw std::invalid_argument(session_name(session) + " has no samples");
    return links.front().id;
  }
  std::map<std::int64_t, std::uint64_t> count;
  store.for_each_sample(session, std::nullopt, [&](const protocol::Sample& s) { ++count[s.link_id]; });
  if (count.empty()) throw std::invalid_argument(session_name(session) + " has no samples");
  // The most samples; among equals the lowest id (max_element keeps the first maximum of the id-ordered map).
  return std::max_element(count.begin(), count.end(), [](const auto& a, const auto& b) { return a.second < b.second; })
      ->first;
}

struct Reference {
  std::vector<std::int64_t> t_ns;
  std::vector<Vector3d> position, velocity;
  std::vector<Quaterniond> attitude;
  bool has_all_velocities = true;
  std::uint64_t rows = 0, rows_dropped = 0;  // SessionSeriesCounts' reference_rows and reference_rows_dropped
};

Reference read_reference(const store::Store& store, std::int64_t session) {
  Reference r;
  store.for_each_reference(session, [&](const store::ReferenceRow& row) {
    ++r.rows;
    const Vector3d position = vector_of(row.position);
    Quaterniond q(row.quat_wxyz[0], row.quat_wxyz[1], row.quat_wxyz[2], row.quat_wxyz[3]);
    const bool usable = position.allFinite() && q.coeffs().allFinite() && q.norm() > 0.0 &&
                        (!row.velocity || vector_of(*row.velocity).allFinite()) &&
                        (r.t_ns.empty() || row.t_ns > r.t_ns.back());
    if (!usable) {
      ++r.rows_dropped;
      return;
    }
    r.t_ns.push_back(row.t_ns);
    r.position.push_back(position);
    r.attitude.push_back(q.normalized());  // stored quaternions may carry rounding; the estimator wants unit ones
    r.velocity.push_back(row.velocity ? vector_of(*row.velocity) : Vector3d::Zero());
    r.has_all_velocities = r.has_all_velocities && row.velocity.has_value();
  });
  if (r.t_ns.size() < 2) return r;  // no trajectory: the caller decides whether that is an error
  if (!r.has_all_velocities) {
    std::vector<double> t(r.t_ns.size());
    for (std::size_t i = 0; i < t.size(); ++i) t[i] = static_cast<double>(r.t_ns[i] - r.t_ns.front()) * 1e-9;
    r.velocity = estimator::central_difference(t, r.position);
  }
  return r;
}

// What the link's recorded config declares; "auto" when the session predates the key or records no links.
std::string declared_axes(const store::Store& store, std::int64_t session, std::int64_t link_id) {
  std::string config;
  for (const store::Session& s : store.sessions()) {
    if (s.id == session) config = s.info.config;
  }
  std::string name;
  for (const store::Link& l : store.links(session)) {
    if (l.id == link_id) name = l.name;
  }
  try {
    for (const pipeline::RecordedLink& l : pipeline::recorded_links(config)) {
      if (l.name == name) return l.imu_axes;
    }
  } catch (const std::invalid_argument&) {
    // A snapshot without links (TOML, or older writers): nothing declared.
  }
  return "auto";
}

// Resolves the axes on the samples as read (IMU axes), then rotates them and the reference into body axes.
void to_body_axes(SessionSeries& out, const std::string& declared) {
  const estimator::ImuAxes axes = estimator::parse_imu_axes(declared);
  out.axes = estimator::resolve_axes(axes, estimator::detect_up(out.series));
  if (out.axes.mismatch) out.warnings.push_back(*out.axes.mismatch);
  if (out.axes.note) out.warnings.push_back(*out.axes.note);
  const Eigen::Matrix3d& r_bs = out.axes.axes.imu_to_body;
  Eigen::Matrix3d ref_from_imu = Eigen::Matrix3d::Identity();
  if (out.series.reference) {
    out.reference_alignment = estimator::align_reference_frame(out.series, r_bs);
    ref_from_imu = out.reference_alignment->ref_from_imu;
    const auto frame = out.reference_alignment->frame;
    // Nothing to say when both hypotheses are the same frame (an FRD IMU) and the data agree.
    const bool ambiguous = frame == estimator::ReferenceFrame::cannot_tell && r_bs != Eigen::Matrix3d::Identity();
    if (ambiguous || frame == estimator::ReferenceFrame::estimated)
      out.warnings.push_back(estimator::describe(*out.reference_alignment) +
                             (ambiguous ? ": taken as the IMU's" : ": neither the IMU's nor the body's"));
  }
  estimator::rotate_to_body(out.series, r_bs, ref_from_imu);
}

// The pose pair around `at_ns` and where between them: t_ns[i] <= at <= t_ns[i + 1]; nullopt outside the poses.
std::optional<std::pair<std::size_t, double>> pose_around(const Reference& reference, std::int64_t at_ns) {
  if (at_ns < reference.t_ns.front() || at_ns > reference.t_ns.back()) return std::nullopt;
  const std::size_t i = std::min<std::size_t>(
      std::upper_bound(reference.t_ns.begin(), reference.t_ns.end(), at_ns) - reference.t_ns.begin() - 1,
      reference.t_ns.size() - 2);
  return std::pair{i, static_cast<double>(at_ns - reference.t_ns[i]) /
                          static_cast<double>(reference.t_ns[i + 1] - reference.t_ns[i])};
}

constexpr double kMaxDeclaredDelay = 10.0;  // s

// The session's monotonic clock (recv_mono_ns, reference and event times) on the series' clock: the samples' device
// time as a straight-line function of their reception time (least squares), so a live link's reception jitter moves
// nothing.
class SeriesClock {
 public:
  SeriesClock(const std::vector<double>& t, const std::vector<std::int64_t>& recv_ns) : origin_(recv_ns.front()) {
    for (std::size_t k = 0; k < t.size(); ++k) mean_x_ += seconds(recv_ns[k]), mean_y_ += t[k];
    mean_x_ /= static_cast<double>(t.size());
    mean_y_ /= static_cast<double>(t.size());
    double sxx = 0.0, sxy = 0.0;
    for (std::size_t k = 0; k < t.size(); ++k) {
      sxx += (seconds(recv_ns[k]) - mean_x_) * (seconds(recv_ns[k]) - mean_x_);
      sxy += (seconds(recv_ns[k]) - mean_x_) * (t[k] - mean_y_);
    }
    slope_ = sxx > 0.0 ? sxy / sxx : 1.0;
  }
  double at(std::int64_t ns) const { return mean_y_ + slope_ * (seconds(ns) - mean_x_); }

 private:
  double seconds(std::int64_t ns) const { return static_cast<double>(ns - origin_) * 1e-9; }
  std::int64_t origin_;
  double mean_x_ = 0.0, mean_y_ = 0.0, slope_ = 1.0;
};

// When the log's own land detector says the vehicle flew: its takeoff and landing events, paired in time order (a
// takeoff without a landing flies to the end; a landing without a takeoff from the start). nullopt without either.
std::optional<std::vector<estimator::TimeWindow>> airborne_from_events(const store::Store& store, std::int64_t session,
                                                                       const SeriesClock& clock) {
  const std::vector<store::Event> events = pipeline::land_detector_events(store.events(session));
  if (events.empty()) return std::nullopt;
  constexpr double kForever = std::numeric_limits<double>::infinity();
  std::vector<estimator::TimeWindow> out;
  std::optional<double> takeoff;
  bool first = true;
  for (const store::Event& e : events) {
    const double t = clock.at(e.mono_ns);
    if (e.kind == "takeoff") {
      if (!takeoff) takeoff = t;
    } else if (takeoff || first) {
      out.push_back({takeoff.value_or(-kForever), t});
      takeoff.reset();
    }
    first = false;
  }
  if (takeoff) out.push_back({*takeoff, kForever});
  return out;
}

// Where the land detector says the vehicle stood: before its first takeoff, between its flights, after its last
// landing (everywhere when it never flew).
std::vector<estimator::TimeWindow> landed_between(const std::vector<estimator::TimeWindow>& airborne) {
  constexpr double kForever = std::numeric_limits<double>::infinity();
  std::vector<estimator::TimeWindow> out;
  double from = -kForever;
  for (const estimator::TimeWindow& flight : airborne) {
    if (flight.start > from) out.push_back({from, flight.start});
    from = std::max(from, flight.end);
  }
  if (from < kForever) out.push_back({from, kForever});
  return out;
}

// Estimates the delay unless declared, says so, and re-takes every sample's reference velocity at its reception
// time plus the delay.
void apply_reference_delay(SessionSeries& out, const Reference& reference, const std::vector<std::int64_t>& recv_ns,
                           const std::optional<double>& declared) {
  estimator::ImuSeries& series = out.series;
  if (declared) {
    out.reference_shift_s = *declared;
    char line[120];
    std::snprintf(line, sizeof line, "reference delay: %g s as declared (--reference-delay), the reference is %s",
                  *declared, *declared == 0.0 ? "not shifted" : "shifted by it");
    out.reference_delay_line = line;
  } else {
    const SeriesClock clock(series.t, recv_ns);
    std::vector<double> pose_t;
    for (const std::int64_t ns : reference.t_ns) pose_t.push_back(clock.at(ns));
    out.reference_delay = estimator::estimate_reference_delay(series, pose_t, reference.velocity);
    const estimator::ReferenceDelay& d = *out.reference_delay;
    out.reference_delay_line = "reference delay: " + estimator::describe(d);
    // Less than one IMU sample of delay changes no pairing worth the samples a shift drops at the ends.
    std::vector<double> steps(series.t.size() > 1 ? series.t.size() - 1 : 0);
    for (std::size_t k = 0; k < steps.size(); ++k) steps[k] = series.t[k + 1] - series.t[k];
    std::nth_element(steps.begin(), steps.begin() + static_cast<long>(steps.size() / 2), steps.end());
    const double sample_period = steps.empty() ? 0.0 : steps[steps.size() / 2];
    if (d.usable() && std::abs(d.delay_s) < sample_period) {
      char line[120];
      std::snprintf(line, sizeof line, ", less than one IMU sample (%.3f s): the reference is not shifted",
                    sample_period);
      out.reference_delay_line += line;
    } else if (d.usable()) {
      out.reference_shift_s = d.delay_s;
      out.reference_delay_line += ", the reference is shifted by it";
    } else {
      out.reference_delay_line += ": the reference is not shifted (declare it with --reference-delay S)";
    }
  }
  if (out.reference_shift_s == 0.0) return;
  const auto shift_ns = static_cast<std::int64_t>(std::llround(out.reference_shift_s * 1e9));
  std::size_t kept = 0;
  for (std::size_t k = 0; k < series.size(); ++k) {
    const auto pose = pose_around(reference, recv_ns[k] + shift_ns);
    if (!pose) {
      ++out.counts.outside_reference;
      continue;
    }
    const auto [i, f] = *pose;
    series.t[kept] = series.t[k];
    series.gyro[kept] = series.gyro[k];
    series.accel[kept] = series.accel[k];
    series.reference->attitude[kept] = series.reference->attitude[k];
    series.reference->velocity_ned[kept] = (1.0 - f) * reference.velocity[i] + f * reference.velocity[i + 1];
    ++kept;
  }
  if (kept == 0)
    throw std::invalid_argument("no sample is left inside the reference once it is shifted by the reference delay");
  series.t.resize(kept);
  series.gyro.resize(kept);
  series.accel.resize(kept);
  series.reference->attitude.resize(kept);
  series.reference->velocity_ned.resize(kept);
}

// The reference read on a connection of its own while the caller reads the samples: the two reads are most of a
// session's reading, and independent. Nothing (an invalid future) when the store has no second connection to give.
std::future<Reference> start_reading_reference(const store::Store& store, std::int64_t session) {
  const std::optional<std::filesystem::path> path = store.second_reader_path();
  if (!path) return {};
  return std::async(std::launch::async, [path = *path, session] {
    const store::Store reader(path, {.read_only = true});
    return read_reference(reader, session);
  });
}

// The link's usable samples into out.series, counted; returns each one's reception time.
std::vector<std::int64_t> read_samples(const store::Store& store, std::int64_t session, SessionSeries& out) {
  estimator::ImuSeries& series = out.series;
  std::vector<std::int64_t> recv_mono_ns;
  std::optional<std::int64_t> first_us, last_us;
  store.for_each_motion_sample(session, out.link_id, [&](const protocol::Sample& s) {
    ++out.counts.samples;
    const Vector3d gyro = vector_of(s.gyro), accel = vector_of(s.accel);
    if (!gyro.allFinite() || !accel.allFinite()) {
      ++out.counts.non_finite;
      return;
    }
    if (last_us && s.device_time_us <= *last_us) {
      ++out.counts.time_not_increasing;
      return;
    }
    if (!first_us) first_us = s.device_time_us;
    last_us = s.device_time_us;
    series.t.push_back(static_cast<double>(s.device_time_us - *first_us) * 1e-6);
    series.gyro.push_back(gyro);
    series.accel.push_back(accel);
    recv_mono_ns.push_back(s.recv_mono_ns);
  });
  if (series.size() == 0) throw std::invalid_argument(session_name(session) + " has no usable samples");
  return recv_mono_ns;
}

// Keeps the samples received while the reference was recorded, each with the reference interpolated at its
// reception time; returns their reception times.
std::vector<std::int64_t> keep_inside_reference(SessionSeries& out, const Reference& reference,
                                                const std::vector<std::int64_t>& recv_mono_ns, std::int64_t session) {
  const estimator::ImuSeries& series = out.series;
  estimator::ImuSeries kept;
  kept.reference.emplace();
  std::vector<std::int64_t> kept_recv_ns;
  for (std::size_t k = 0; k < series.size(); ++k) {
    const std::int64_t at = recv_mono_ns[k];
    const auto pose = pose_around(reference, at);
    if (!pose) {
      ++out.counts.outside_reference;
      continue;
    }
    const auto [i, f] = *pose;
    kept.t.push_back(series.t[k]);
    kept.gyro.push_back(series.gyro[k]);
    kept.accel.push_back(series.accel[k]);
    kept.reference->velocity_ned.push_back((1.0 - f) * reference.velocity[i] + f * reference.velocity[i + 1]);
    kept.reference->attitude.push_back(reference.attitude[i].slerp(f, reference.attitude[i + 1]).normalized());
    kept_recv_ns.push_back(at);
  }
  if (kept.size() == 0)
    throw std::invalid_argument(session_name(session) + ": no sample was received while the reference was recorded");
  kept.landed = std::move(out.series.landed);  // on the same clock
  out.series = std::move(kept);
  return kept_recv_ns;
}

}  // namespace

SessionSeries read_session_series(const store::Store& store, std::int64_t session,
                                  const SessionSeriesOptions& options) {
  const std::vector<store::Session> sessions = store.sessions();
  if (std::none_of(sessions.begin(), sessions.end(), [&](const store::Session& s) { return s.id == session; }))
    throw std::invalid_argument("no " + session_name(session) + " in the database");
  SessionSeries out;
  out.link_id = choose_link(store, session, options.link);

  const std::string declared = options.imu_axes ? *options.imu_axes : declared_axes(store, session, out.link_id);
  estimator::parse_imu_axes(declared);  // a bad spelling fails before the work
  std::future<Reference> reference_read;
  if (options.reference != ReferenceUse::none) reference_read = start_reading_reference(store, session);
  const std::vector<std::int64_t> recv_mono_ns = read_samples(store, session, out);
  out.flight = estimator::flight_identity(out.series);
  out.airborne = airborne_from_events(store, session, SeriesClock(out.series.t, recv_mono_ns));
  if (out.airborne) out.series.landed = landed_between(*out.airborne);
  if (options.reference == ReferenceUse::none) {
    to_body_axes(out, declared);
    return out;
  }

  const Reference reference = reference_read.valid() ? reference_read.get() : read_reference(store, session);
  out.counts.reference_rows = reference.rows;
  out.counts.reference_rows_dropped = reference.rows_dropped;
  if (options.reference == ReferenceUse::when_present && out.counts.reference_rows < 2) {
    to_body_axes(out, declared);
    return out;
  }
  if (reference.t_ns.size() < 2) throw std::invalid_argument(session_name(session) + " has no reference trajectory");
  if (options.reference_delay && !(std::abs(*options.reference_delay) <= kMaxDeclaredDelay))
    throw std::invalid_argument("a reference delay must be within +-10 s (it is a receiver's latency)");
  const std::vector<std::int64_t> kept_recv_ns = keep_inside_reference(out, reference, recv_mono_ns, session);
  to_body_axes(out, declared);
  if (options.reference_delay || options.estimate_reference_delay)
    apply_reference_delay(out, reference, kept_recv_ns, options.reference_delay);
  return out;
}

}  // namespace imubridge::replay
