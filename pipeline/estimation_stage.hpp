#pragma once
// Samples -> estimates: lever-arm compensation and the drag-velocity estimator, one estimator per stream of samples
// (protocol::SourceKey: a link, or one XBee radio of it), so samples of different vehicles never mix. Live runs and
// replay drive this same object, so the same samples and parameters give bit-identical estimates. Estimates leave with
// no store link (link_id 0): they belong to their sample's source, and whoever stores them knows its store link.
#include <Eigen/Core>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <span>
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
  // By the link's index (SourceKey::link): an XBee radio's IMU sits as declared for the link it is heard through.
  std::map<std::uint32_t, estimator::ImuAxes> links{};
  estimator::ImuAxes others = estimator::auto_axes();  // links not listed
  // Called once per source when its axes are resolved (auto) or checked (declared); resolution.mismatch says the
  // data disagree with a declaration.
  std::function<void(const protocol::SourceKey& source, const estimator::AxesResolution& resolution)> on_resolved{};
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
  // End of data: links still waiting decide on what they have (the mean specific force) and release their samples'
  // estimates, given to `released` source by source.
  using Released = std::function<void(const protocol::SourceKey& source, std::span<const store::Estimate> estimates)>;
  void finish(const Released& released);
  // The same, every source's estimates appended to `out`.
  void finish(std::vector<store::Estimate>& out);

  // The autopilot's land detector for link `link` (SourceKey::link, every source heard through it): the estimators
  // fuse rest while it says landed (estimator::DragVelocityEstimator::set_landed). A sample waiting for its link's
  // axes is estimated with the state it arrived in.
  void set_landed(std::uint32_t link, bool landed);

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
    struct Held {
      protocol::Sample sample;
      bool landed = false;  // the land detector's state when it came
    };
    std::vector<Held> waiting{};    // an auto link's samples until its axes are decided
    std::uint32_t clock_epoch = 0;  // the device's restarts so far (protocol::Sample)
    std::optional<std::int64_t> last_recv_mono_ns{};
  };

  LinkState& link(const protocol::SourceKey& source);
  // The source's axes from `detection` (and its declaration): the detector is done, and on_resolved hears it.
  void resolve(const protocol::SourceKey& source, LinkState& link,
               const std::optional<estimator::AxesDetection>& detection);
  // An auto source's samples held until its axes were decided, estimated now into `out`.
  void release_waiting(LinkState& link, std::vector<store::Estimate>& out);
  std::optional<store::Estimate> estimate(LinkState& link, const protocol::Sample& sample, bool landed);

  estimator::ModelParams params_;
  estimator::DragVelocityConfig config_;
  std::optional<StageAxes> axes_;
  std::map<protocol::SourceKey, LinkState> links_;
  std::set<std::uint32_t> landed_links_;  // set_landed
};

}  // namespace imubridge::pipeline
