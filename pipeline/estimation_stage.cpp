#include "pipeline/estimation_stage.hpp"

namespace imubridge::pipeline {

EstimationStage::EstimationStage(const estimator::ModelParams& params)
    : EstimationStage(params, estimator::config_for(params)) {}

EstimationStage::EstimationStage(const estimator::ModelParams& params, const estimator::DragVelocityConfig& config)
    : params_(params), config_(config) {
  estimator::DragVelocityEstimator check(params_.full, config_);  // bad parameters fail here, not mid-flight
}

int EstimationStage::delay_samples() const { return (config_.differentiator_window - 1) / 2; }

std::optional<store::Estimate> EstimationStage::update(const protocol::Sample& sample) {
  auto it = links_.find(sample.link_id);
  if (it == links_.end()) {
    it = links_.emplace(sample.link_id, LinkState{estimator::DragVelocityEstimator(params_.full, config_), {}}).first;
  }
  LinkState& link = it->second;
  const double t = static_cast<double>(sample.device_time_us) * 1e-6;
  const estimator::ImuSample input{t, {sample.gyro[0], sample.gyro[1], sample.gyro[2]},
                                   {sample.accel[0], sample.accel[1], sample.accel[2]}};
  const auto rejected = [&link] {
    const auto& c = link.estimator.counters();
    return c.rejected_non_finite + c.rejected_out_of_range + c.rejected_time;
  };
  const std::uint64_t rejected_before = rejected();
  const auto estimate = link.estimator.update(input);
  if (rejected() != rejected_before) return std::nullopt;  // counted by the estimator, never to be estimated
  link.pending.emplace_back(t, sample.seq);
  if (!estimate) return std::nullopt;  // warming up the differentiator window
  // The estimate belongs to the pending sample with its time; older ones fell into a gap that restarted the window.
  while (!link.pending.empty() && link.pending.front().first < estimate->t) link.pending.pop_front();
  if (link.pending.empty() || link.pending.front().first != estimate->t) return std::nullopt;
  const std::uint64_t seq = link.pending.front().second;
  link.pending.pop_front();
  return store::Estimate{.link_id = sample.link_id,
                         .seq = seq,
                         .t_s = estimate->t,
                         .fx = estimate->f.x(),
                         .fy = estimate->f.y(),
                         .vx = estimate->v.x(),
                         .vy = estimate->v.y(),
                         .var_vx = estimate->v_var.x(),
                         .var_vy = estimate->v_var.y()};
}

}  // namespace imubridge::pipeline
