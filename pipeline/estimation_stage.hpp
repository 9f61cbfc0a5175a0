#pragma once
// Samples -> estimates: lever-arm compensation and the drag-velocity estimator, one estimator per link (samples of
// different vehicles never mix). Live runs and replay drive this same object, so the same samples and parameters
// give bit-identical estimates.
#include <cstdint>
#include <deque>
#include <map>
#include <optional>

#include "estimator/drag_velocity.hpp"
#include "estimator/params.hpp"
#include "protocol/sample.hpp"
#include "store/records.hpp"

namespace imubridge::pipeline {

class EstimationStage {
 public:
  // The filter's settings follow the identification (estimator::config_for) unless given.
  explicit EstimationStage(const estimator::ModelParams& params);
  EstimationStage(const estimator::ModelParams& params, const estimator::DragVelocityConfig& config);

  // The estimate this sample completes, if any. The estimator looks delay_samples() back (its differentiator is
  // centred there), so an estimate describes an earlier sample: its seq and time are that sample's.
  std::optional<store::Estimate> update(const protocol::Sample& sample);

  const estimator::ModelParams& params() const { return params_; }
  int delay_samples() const;

 private:
  struct LinkState {
    estimator::DragVelocityEstimator estimator;
    std::deque<std::pair<double, std::uint64_t>> pending;  // (time, seq) of samples not yet estimated
  };

  estimator::ModelParams params_;
  estimator::DragVelocityConfig config_;
  std::map<std::uint32_t, LinkState> links_;
};

}  // namespace imubridge::pipeline
