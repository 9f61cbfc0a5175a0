#include "pipeline/estimation_stage.hpp"

#include <cmath>
#include <stdexcept>
#include <utility>

namespace imubridge::pipeline {

EstimationStage::EstimationStage(const estimator::ModelParams& params)
    : EstimationStage(params, estimator::config_for(params)) {}

EstimationStage::EstimationStage(const estimator::ModelParams& params, const estimator::DragVelocityConfig& config)
    : params_(params), config_(config) {
  estimator::DragVelocityEstimator check(params_.full, config_);  // bad parameters fail here, not mid-flight
}

EstimationStage::EstimationStage(const estimator::ModelParams& params, StageAxes axes)
    : EstimationStage(params, estimator::config_for(params), std::move(axes)) {}

EstimationStage::EstimationStage(const estimator::ModelParams& params, const estimator::DragVelocityConfig& config,
                                 StageAxes axes)
    : EstimationStage(params, config) {
  axes_ = std::move(axes);
}

int EstimationStage::delay_samples() const { return (config_.differentiator_window - 1) / 2; }

EstimationStage::LinkState& EstimationStage::link(const protocol::SourceKey& source) {
  auto it = links_.find(source);
  if (it != links_.end()) return it->second;
  LinkState state{estimator::DragVelocityEstimator(params_.full, config_), {}};
  if (axes_) {
    const auto declared = axes_->links.find(source.link);
    state.declared = declared != axes_->links.end() ? declared->second : axes_->others;
    state.detector.emplace();
    if (!state.declared.automatic) {
      state.imu_to_body = state.declared.imu_to_body;
      state.rotate = !estimator::is_identity(state.declared);
    }
  }
  return links_.emplace(source, std::move(state)).first->second;
}

void EstimationStage::resolve(const protocol::SourceKey& source, LinkState& link,
                              const std::optional<estimator::AxesDetection>& detection) {
  const estimator::AxesResolution resolution = estimator::resolve_axes(link.declared, detection);
  link.detector.reset();
  link.imu_to_body = resolution.axes.imu_to_body;
  link.rotate = !estimator::is_identity(resolution.axes);
  if (axes_->on_resolved) axes_->on_resolved(source, resolution);
}

void EstimationStage::update(const protocol::Sample& sample, std::vector<store::Estimate>& out) {
  LinkState& state = link(sample.source);
  if (state.detector) {
    const Eigen::Vector3d accel(sample.accel[0], sample.accel[1], sample.accel[2]);
    const Eigen::Vector3d gyro(sample.gyro[0], sample.gyro[1], sample.gyro[2]);
    // A corrupt sample says nothing about gravity; the estimator counts it when its turn comes.
    const bool decided = accel.allFinite() && gyro.allFinite() &&
                         state.detector->add(static_cast<double>(sample.device_time_us) * 1e-6, accel, gyro);
    if (state.declared.automatic) {
      state.waiting.push_back({sample, landed_links_.contains(sample.source.link)});
      if (!decided) return;
      resolve(sample.source, state, state.detector->result());
      release_waiting(state, out);
      return;
    }
    if (decided) resolve(sample.source, state, state.detector->result());
  }
  if (auto e = estimate(state, sample, landed_links_.contains(sample.source.link))) out.push_back(*e);
}

void EstimationStage::set_landed(std::uint32_t link, bool landed) {
  if (landed) {
    landed_links_.insert(link);
  } else {
    landed_links_.erase(link);
  }
}

void EstimationStage::release_waiting(LinkState& link, std::vector<store::Estimate>& out) {
  std::vector<LinkState::Held> waiting = std::move(link.waiting);
  link.waiting = {};
  for (const LinkState::Held& held : waiting) {
    if (auto e = estimate(link, held.sample, held.landed)) out.push_back(*e);
  }
}

std::optional<store::Estimate> EstimationStage::update(const protocol::Sample& sample) {
  std::vector<store::Estimate> out;
  update(sample, out);
  if (out.size() > 1) {
    throw std::logic_error("EstimationStage::update: a link released several estimates; use update(sample, out)");
  }
  if (out.empty()) return std::nullopt;
  return out.front();
}

void EstimationStage::finish(std::vector<store::Estimate>& out) {
  finish([&out](const protocol::SourceKey&, std::span<const store::Estimate> estimates) {
    out.insert(out.end(), estimates.begin(), estimates.end());
  });
}

void EstimationStage::finish(const Released& released) {
  std::vector<store::Estimate> out;
  for (auto& [source, state] : links_) {
    if (!state.detector) continue;
    std::optional<estimator::AxesDetection> detection = state.detector->result();
    if (!state.detector->decided()) {
      // Decide on the mean specific force of what came: the detector's own flight rule, applied early.
      std::vector<double> t;
      std::vector<Eigen::Vector3d> accel, gyro;
      for (const auto& [s, landed] : state.waiting) {
        const Eigen::Vector3d a(s.accel[0], s.accel[1], s.accel[2]), w(s.gyro[0], s.gyro[1], s.gyro[2]);
        if (!a.allFinite() || !w.allFinite() || (!t.empty() && s.device_time_us * 1e-6 <= t.back())) continue;
        t.push_back(static_cast<double>(s.device_time_us) * 1e-6);
        accel.push_back(a);
        gyro.push_back(w);
      }
      detection = estimator::detect_up(t, accel, gyro);
    }
    resolve(source, state, detection);
    out.clear();
    release_waiting(state, out);
    if (!out.empty()) released(source, out);
  }
}

std::optional<store::Estimate> EstimationStage::estimate(LinkState& link, const protocol::Sample& sample, bool landed) {
  if (sample.clock_epoch != link.clock_epoch) {
    // The device restarted: its times count from zero again. The samples still in the window before it will get no
    // estimate, as before a gap; every one after it will.
    const double elapsed =
        link.last_recv_mono_ns ? static_cast<double>(sample.recv_mono_ns - *link.last_recv_mono_ns) * 1e-9 : 0.0;
    link.estimator.restart_clock(elapsed);
    link.pending.clear();
    link.clock_epoch = sample.clock_epoch;
  }
  link.last_recv_mono_ns = sample.recv_mono_ns;
  const double t = static_cast<double>(sample.device_time_us) * 1e-6;
  estimator::ImuSample input{
      t, {sample.gyro[0], sample.gyro[1], sample.gyro[2]}, {sample.accel[0], sample.accel[1], sample.accel[2]}};
  if (link.rotate) {
    input.gyro = link.imu_to_body * input.gyro;
    input.accel = link.imu_to_body * input.accel;
  }
  const auto rejected = [&link] {
    const auto& c = link.estimator.counters();
    return c.rejected_non_finite + c.rejected_out_of_range + c.rejected_time;
  };
  const std::uint64_t rejected_before = rejected();
  link.estimator.set_landed(landed);
  const auto estimate = link.estimator.update(input);
  if (rejected() != rejected_before) return std::nullopt;  // counted by the estimator, never to be estimated
  link.pending.emplace_back(t, sample.seq);
  if (!estimate) return std::nullopt;  // warming up the differentiator window
  // The estimate belongs to the pending sample with its time; older ones fell into a gap that restarted the window.
  while (!link.pending.empty() && link.pending.front().first < estimate->t) link.pending.pop_front();
  if (link.pending.empty() || link.pending.front().first != estimate->t) return std::nullopt;
  const std::uint64_t seq = link.pending.front().second;
  link.pending.pop_front();
  return store::Estimate{.seq = seq,
                         .t_s = estimate->t,
                         .fx = estimate->f.x(),
                         .fy = estimate->f.y(),
                         .vx = estimate->v.x(),
                         .vy = estimate->v.y(),
                         .var_vx = estimate->v_var.x(),
                         .var_vy = estimate->v_var.y()};
}

}  // namespace imubridge::pipeline
