// gyro_bias: a constant offset of the gyro. It enters the centripetal term and, through eq. (11)'s integrated tilt,
// eq. (12)'s velocity; with the reference as the velocity it is measured against the reference's attitude instead
// (docs/effects.md).
#include <algorithm>

#include "diagnose/effects/library.hpp"

namespace imubridge::diagnose {
namespace {

// The gyro axes the model uses: the paper's pitch axis (x) reads gyro y, its roll axis (y) gyro x; the full model
// all three.
std::vector<int> gyro_axes(const ModelSetup& setup) {
  if (setup.base == ModelKind::full) return {0, 1, 2};
  std::vector<int> axes;
  for (int axis : setup.axes) axes.push_back(axis == 0 ? 1 : 0);
  return axes;
}

class GyroBias final : public Effect {
 public:
  std::string_view name() const override { return "gyro_bias"; }
  Stages stages() const override { return {.gyro = true}; }
  // With the reference's attitude the bias is measured, not fitted (ModelSetup::reference_gyro_bias): no parameters.
  std::vector<Parameter> parameters(const ModelSetup& setup) const override {
    std::vector<Parameter> out;
    if (setup.reference_gyro_bias) return out;
    for (int axis : gyro_axes(setup)) out.push_back({"bias." + axis_name(axis), "rad/s", 0.0, -1.0, 1.0});
    return out;
  }
  // A hovering vehicle's roll and pitch stay bounded, so over the training window its mean roll and pitch rates are
  // the gyro's bias: from zero, eq. (12)'s velocity can be so far off that the fit finds no way back. The yaw may
  // turn freely and starts at zero.
  std::optional<std::string> start(const StartContext& ctx, std::span<double> p) const override {
    if (ctx.setup.reference_gyro_bias) return std::nullopt;
    const Signals& s = *ctx.setup.signals;
    const std::size_t first =
        static_cast<std::size_t>(std::lower_bound(s.t.begin(), s.t.end(), ctx.t.front()) - s.t.begin());
    const Eigen::Matrix3d imu_to_body = level_rotation(s);
    Eigen::Vector3d mean_body = Eigen::Vector3d::Zero();
    for (std::size_t k = first; k < first + ctx.t.size(); ++k) mean_body += imu_to_body * s.gyro[k];
    mean_body /= static_cast<double>(ctx.t.size());
    mean_body.z() = 0.0;
    const Eigen::Vector3d mean_imu = imu_to_body.transpose() * mean_body;
    const std::vector<int> axes = gyro_axes(ctx.setup);
    for (std::size_t i = 0; i < axes.size(); ++i) p[i] = mean_imu[axes[i]];
    return std::nullopt;
  }
  void adjust_gyro(std::span<const double> p, const ModelSetup& setup,
                   std::vector<Eigen::Vector3d>& gyro) const override {
    if (setup.reference_gyro_bias) {
      for (Eigen::Vector3d& w : gyro) w -= *setup.reference_gyro_bias;
      return;
    }
    const std::vector<int> axes = gyro_axes(setup);
    for (Eigen::Vector3d& w : gyro) {
      for (std::size_t i = 0; i < axes.size(); ++i) w[axes[i]] -= p[i];
    }
  }
  std::string live_path(const Parameter& p) const override { return per_axis_live_path("gyro_bias", p); }
  void to_live(std::span<const double> v, std::span<const Parameter> p, const LiveContext& context,
               estimator::FullModelParams& live) const override {
    // Measured, the bias is known on all three axes, the ones the paper model does not use included.
    if (context.setup.reference_gyro_bias) {
      live.gyro_bias += *context.setup.reference_gyro_bias;
      return;
    }
    add_per_axis(v, p, live.gyro_bias);
  }
};

}  // namespace

std::unique_ptr<Effect> make_gyro_bias() { return std::make_unique<GyroBias>(); }

}  // namespace imubridge::diagnose
