// accel_scale: each horizontal accelerometer axis reads (1 + s) times its specific force (docs/effects.md).
#include "diagnose/effects/library.hpp"

namespace imubridge::diagnose {
namespace {

class AccelScale final : public Effect {
 public:
  std::string_view name() const override { return "accel_scale"; }
  Stages stages() const override { return {.sensor = true}; }
  std::optional<std::string> why_not(const ModelSetup& setup, std::span<const std::string>) const override {
    // Eq. (14) is linear in g sin(alpha), r cos(beta), r sin(beta) and mu, all per axis: scaling the axis scales them.
    if (setup.base == ModelKind::paper) return "absorbed by eq. (14)'s per-axis r, alpha and mu";
    return std::nullopt;
  }
  std::vector<Parameter> parameters(const ModelSetup& setup) const override {
    std::vector<Parameter> out;
    for (int axis : setup.axes)
      out.push_back({"scale." + axis_name(setup.signals->horizontal_sensor_axes[axis]), "", 0.0, -0.5, 0.5});
    return out;
  }
  void adjust_sensor(std::span<const double> p, const ModelSetup& setup, std::span<Eigen::Vector3d> predicted,
                     std::span<const Eigen::Vector3d>) const override {
    for (std::size_t i = 0; i < setup.axes.size(); ++i) {
      const int sensor = setup.signals->horizontal_sensor_axes[setup.axes[i]];
      for (Eigen::Vector3d& f : predicted) f[sensor] *= 1.0 + p[i];
    }
  }
  std::string live_path(const Parameter& p) const override { return per_axis_live_path("accel_scale", p); }
  void to_live(std::span<const double> v, std::span<const Parameter> p, const LiveContext&,
               estimator::FullModelParams& live) const override {
    add_per_axis(v, p, live.accel_scale);
  }
};

}  // namespace

std::unique_ptr<Effect> make_accel_scale() { return std::make_unique<AccelScale>(); }

}  // namespace imubridge::diagnose
