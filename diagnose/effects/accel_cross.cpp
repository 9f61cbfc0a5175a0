// accel_cross: each horizontal accelerometer axis also reads a fraction c of the other horizontal axis
// (docs/effects.md). Coupling from the thrust axis is a constant times T, which the sensor tilt already carries.
#include "diagnose/effects/library.hpp"

namespace imubridge::diagnose {
namespace {

class AccelCross final : public Effect {
 public:
  std::string_view name() const override { return "accel_cross"; }
  Stages stages() const override { return {.sensor = true}; }
  std::vector<Parameter> parameters(const ModelSetup& setup) const override {
    const auto& sensor = setup.signals->horizontal_sensor_axes;
    std::vector<Parameter> out;
    for (int axis : setup.axes)
      out.push_back({"cross." + axis_name(sensor[axis]) + axis_name(sensor[1 - axis]), "", 0.0, -0.5, 0.5});
    return out;
  }
  // The other axis's specific force is its measurement, to first order in c (the coupling is small): the paper
  // model does not predict an axis it does not diagnose.
  void adjust_sensor(std::span<const double> p, const ModelSetup& setup, std::span<Eigen::Vector3d> predicted,
                     std::span<const Eigen::Vector3d> measured) const override {
    const auto& sensor = setup.signals->horizontal_sensor_axes;
    for (std::size_t k = 0; k < predicted.size(); ++k) {
      for (std::size_t i = 0; i < setup.axes.size(); ++i) {
        const int axis = setup.axes[i];
        predicted[k][sensor[axis]] += p[i] * measured[k][sensor[1 - axis]];
      }
    }
  }
  // "cross.xy": axis x reads a fraction of axis y.
  std::string live_path(const Parameter& p) const override {
    return "full.accel_cross." + std::to_string(row(p)) + std::to_string(axis_of(p));
  }
  void to_live(std::span<const double> v, std::span<const Parameter> p, const LiveContext&,
               estimator::FullModelParams& live) const override {
    for (std::size_t i = 0; i < p.size(); ++i) live.accel_cross(row(p[i]), axis_of(p[i])) = v[i];
  }

 private:
  static int row(const Parameter& p) { return p.name[p.name.size() - 2] - 'x'; }
};

}  // namespace

std::unique_ptr<Effect> make_accel_cross() { return std::make_unique<AccelCross>(); }

}  // namespace imubridge::diagnose
