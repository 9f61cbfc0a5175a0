// lever_arm_z: the lever arm's z component seen through the tilted sensor axis, the term eq. (14) drops from
// eq. (8) (docs/model.md, docs/effects.md). One z for both axes, as the IMU has one position.
#include <cmath>

#include "diagnose/effects/library.hpp"

namespace imubridge::diagnose {
namespace {

class LeverArmZ final : public Effect {
 public:
  std::string_view name() const override { return "lever_arm_z"; }
  Stages stages() const override { return {.prediction = true}; }
  std::optional<std::string> why_not(const ModelSetup& setup, std::span<const std::string>) const override {
    if (setup.base == ModelKind::full) return "the full model's lever arm is already three-dimensional";
    return std::nullopt;
  }
  std::vector<Parameter> parameters(const ModelSetup&) const override { return {{"z", "m", 0.0, -1.0, 1.0}}; }
  // The sensor's x axis is (cos a, 0, -sin a) in body axes (its y axis (0, cos a, -sin a) for roll), so it reads
  // -sin(a) times the z component of the lever-arm acceleration w_dot x r + w x (w x r), r = (r_x, r_y, z).
  void add_prediction(std::span<const double> p, const PredictionContext& ctx, AxisValues& prediction) const override {
    const double z = p[0];
    for (std::size_t i = 0; i < ctx.setup.axes.size(); ++i) {
      const estimator::PaperAxisParams& axis = ctx.paper[i];
      const double in_plane = axis.r * std::cos(axis.beta);
      const Eigen::Vector3d r =
          ctx.setup.axes[i] == 0 ? Eigen::Vector3d(in_plane, 0.0, z) : Eigen::Vector3d(0.0, in_plane, z);
      const double sin_alpha = std::sin(axis.alpha);
      for (std::size_t k = 0; k < ctx.count; ++k) {
        const Eigen::Vector3d& w = ctx.inputs.gyro[ctx.first + k];
        const Eigen::Vector3d& w_dot = ctx.inputs.gyro_rate[ctx.first + k];
        const double lever_z = (w_dot.cross(r) + w.cross(w.cross(r))).z();
        prediction[i][k] -= sin_alpha * lever_z;
      }
    }
  }
};

}  // namespace

std::unique_ptr<Effect> make_lever_arm_z() { return std::make_unique<LeverArmZ>(); }

}  // namespace imubridge::diagnose
