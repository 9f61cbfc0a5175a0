#include "pipeline/session_series.hpp"

#include <algorithm>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "estimator/differentiator.hpp"
#include "pipeline/session_config.hpp"

namespace imubridge::pipeline {
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
};

Reference read_reference(const store::Store& store, std::int64_t session, SessionSeriesCounts& counts) {
  Reference r;
  store.for_each_reference(session, [&](const store::ReferenceRow& row) {
    ++counts.reference_rows;
    const Vector3d position = vector_of(row.position);
    Quaterniond q(row.quat_wxyz[0], row.quat_wxyz[1], row.quat_wxyz[2], row.quat_wxyz[3]);
    const bool usable = position.allFinite() && q.coeffs().allFinite() && q.norm() > 0.0 &&
                        (!row.velocity || vector_of(*row.velocity).allFinite()) &&
                        (r.t_ns.empty() || row.t_ns > r.t_ns.back());
    if (!usable) {
      ++counts.reference_rows_dropped;
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
    for (const RecordedLink& l : recorded_links(config)) {
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
    const bool ambiguous = frame == estimator::ReferenceFrame::assumed_imu && r_bs != Eigen::Matrix3d::Identity();
    if (ambiguous || frame == estimator::ReferenceFrame::estimated)
      out.warnings.push_back(estimator::describe(*out.reference_alignment) +
                             (ambiguous ? ": taken as the IMU's" : ": neither the IMU's nor the body's"));
  }
  estimator::rotate_to_body(out.series, r_bs, ref_from_imu);
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
  estimator::ImuSeries& series = out.series;
  std::vector<std::int64_t> recv_mono_ns;
  std::optional<std::int64_t> first_us, last_us;
  store.for_each_sample(session, out.link_id, [&](const protocol::Sample& s) {
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
  if (options.reference == ReferenceUse::none) {
    to_body_axes(out, declared);
    return out;
  }

  const Reference reference = read_reference(store, session, out.counts);
  if (options.reference == ReferenceUse::when_present && out.counts.reference_rows < 2) {
    to_body_axes(out, declared);
    return out;
  }
  if (reference.t_ns.size() < 2) throw std::invalid_argument(session_name(session) + " has no reference trajectory");
  estimator::ImuSeries kept;
  kept.reference.emplace();
  for (std::size_t k = 0; k < series.size(); ++k) {
    const std::int64_t at = recv_mono_ns[k];
    if (at < reference.t_ns.front() || at > reference.t_ns.back()) {
      ++out.counts.outside_reference;
      continue;
    }
    // The pose pair around `at`: t_ns[i] <= at <= t_ns[i + 1].
    const std::size_t i = std::min<std::size_t>(
        std::upper_bound(reference.t_ns.begin(), reference.t_ns.end(), at) - reference.t_ns.begin() - 1,
        reference.t_ns.size() - 2);
    const double f =
        static_cast<double>(at - reference.t_ns[i]) / static_cast<double>(reference.t_ns[i + 1] - reference.t_ns[i]);
    kept.t.push_back(series.t[k]);
    kept.gyro.push_back(series.gyro[k]);
    kept.accel.push_back(series.accel[k]);
    kept.reference->velocity_ned.push_back((1.0 - f) * reference.velocity[i] + f * reference.velocity[i + 1]);
    kept.reference->attitude.push_back(reference.attitude[i].slerp(f, reference.attitude[i + 1]).normalized());
  }
  if (kept.size() == 0)
    throw std::invalid_argument(session_name(session) + ": no sample was received while the reference was recorded");
  series = std::move(kept);
  to_body_axes(out, declared);
  return out;
}

}  // namespace imubridge::pipeline
