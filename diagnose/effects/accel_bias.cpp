// accel_bias: a constant offset of the accelerometer on each diagnosed axis (docs/effects.md).
#include "diagnose/effects/library.hpp"

namespace imubridge::diagnose {
namespace {

class AccelBias final : public Effect {
 public:
  std::string_view name() const override { return "accel_bias"; }
  Stages stages() const override { return {.prediction = true}; }
  std::optional<std::string> why_not(const ModelSetup& setup, std::span<const std::string> in_model) const override {
    // g sin(alpha) is a constant too: only a thrust that varies (T sin(alpha)) tells the two apart.
    if (setup.base == ModelKind::paper && !contains(in_model, "thrust"))
      return "indistinguishable from eq. (14)'s g sin(alpha): both add a constant (add thrust first)";
    return std::nullopt;
  }
  std::vector<Parameter> parameters(const ModelSetup& setup) const override {
    return per_axis(setup, "bias", "m/s^2", -20.0, 20.0);
  }
  void add_prediction(std::span<const double> p, const PredictionContext&, AxisValues& prediction) const override {
    for (std::size_t i = 0; i < prediction.size(); ++i) {
      for (double& value : prediction[i]) value += p[i];
    }
  }
  std::string live_path(const Parameter& p) const override { return per_axis_live_path("accel_bias", p); }
  // Fitted in the residual's frame (the full base's body axes): the live estimator's bias is in IMU axes.
  void to_live(std::span<const double> v, std::span<const Parameter> p, const LiveContext& context,
               estimator::FullModelParams& live) const override {
    Eigen::Vector3d body = Eigen::Vector3d::Zero();
    add_per_axis(v, p, body);
    live.accel_bias += context.imu_to_body.transpose() * body;
  }
};

}  // namespace

std::unique_ptr<Effect> make_accel_bias() { return std::make_unique<AccelBias>(); }

}  // namespace imubridge::diagnose
