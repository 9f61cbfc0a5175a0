#pragma once
// Samples -> estimates: lever-arm compensation and the drag-velocity estimator, one estimator per link (samples of
// different vehicles never mix). Live runs and replay drive this same object, so the same samples and parameters
// give bit-identical estimates.
#include <Eigen/Core>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <optional>
#include <vector>

#include "estimator/drag_velocity.hpp"
#include "estimator/imu_axes.hpp"
#include "estimator/params.hpp"
#include "protocol/sample.hpp"
#include "store/records.hpp"

namespace imubridge::pipeline {

// How each link's IMU axes sit in the body (docs/estimator.md, "IMU axes"). Samples are rotated into body axes
// before the estimator. An auto link's first samples wait in the stage until gravity decides its axes (at rest
// for estimator::kRestWindowSeconds, else after estimator::kFlightDecisionSeconds), then go through in order: nothing
// is lost, and the same samples give the same estimates bit for bit. Declared links are checked against gravity the
// same way without waiting.
struct StageAxes {
  std::map<protocol::LinkId, estimator::ImuAxes> links{};  // by link id
  estimator::ImuAxes others = estimator::auto_axes();      // links not listed
  // When set, asked instead of `links` and `others` (for link ids made on the fly, such as one per XBee radio).
  std::function<estimator::ImuAxes(protocol::LinkId link)> declared{};
  // Called once per link when its axes are resolved (auto) or checked (declared); resolution.mismatch says the
  // data disagree with a declaration.
  std::function<void(protocol::LinkId link, const estimator::AxesResolution& resolution)> on_resolved{};
};

class EstimationStage {
 public:
  // The filter's settings follow the identification (estimator::config_for) unless given. Without StageAxes every
  // link is taken as FRD and nothing waits (the behaviour before axes were handled).
  explicit EstimationStage(const estimator::ModelParams& params);
  EstimationStage(const estimator::ModelParams& params, const estimator::DragVelocityConfig& config);
  EstimationStage(const estimator::ModelParams& params, StageAxes axes);
  EstimationStage(const estimator::ModelParams& params, const estimator::DragVelocityConfig& config, StageAxes axes);

  // Appends the estimates this sample completes, in order: none while an auto link waits for its axes, possibly
  // many when they are decided. The estimator looks delay_samples() back (its differentiator is centred there), so
  // an estimate describes an earlier sample: its seq and time are that sample's.
  void update(const protocol::Sample& sample, std::vector<store::Estimate>& out);
  // The same for a stage whose links never wait (no auto link): at most one estimate per sample. Throws
  // std::logic_error if a waiting link released more than one (use the overload above).
  std::optional<store::Estimate> update(const protocol::Sample& sample);
  // End of data: links still waiting decide on what they have (the mean specific force) and release their samples.
  void finish(std::vector<store::Estimate>& out);

  const estimator::ModelParams& params() const { return params_; }
  const std::optional<StageAxes>& axes() const { return axes_; }
  int delay_samples() const;

 private:
  struct LinkState {
    estimator::DragVelocityEstimator estimator;
    std::deque<std::pair<double, std::uint64_t>> pending;  // (time, seq) of samples not yet estimated
    estimator::ImuAxes declared{estimator::frd_axes()};
    Eigen::Matrix3d imu_to_body = Eigen::Matrix3d::Identity();
    bool rotate = false;                              // imu_to_body is not the identity
    std::optional<estimator::UpDetector> detector{};  // until the axes are resolved or checked
    std::vector<protocol::Sample> waiting{};          // an auto link's samples until its axes are decided
    protocol::LinkId clock_epoch = 0;                 // the device's restarts so far (protocol::Sample)
    std::optional<std::int64_t> last_recv_mono_ns{};
  };

  LinkState& link(protocol::LinkId id);
  void resolve(protocol::LinkId id, LinkState& link);
  std::optional<store::Estimate> estimate(LinkState& link, const protocol::Sample& sample);

  estimator::ModelParams params_;
  estimator::DragVelocityConfig config_;
  std::optional<StageAxes> axes_;
  std::map<protocol::LinkId, LinkState> links_;
};

}  // namespace imubridge::pipeline
