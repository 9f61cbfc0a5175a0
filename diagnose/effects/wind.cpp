// wind: a constant air velocity; drag acts on the ground velocity minus the wind (docs/effects.md).
#include <cmath>

#include "diagnose/effects/library.hpp"

namespace imubridge::diagnose {
namespace {

class Wind final : public Effect {
 public:
  std::string_view name() const override { return "wind"; }
  Stages stages() const override { return {.wind = true}; }
  std::optional<std::string> why_not(const ModelSetup& setup, std::span<const std::string> in_model) const override {
    const bool drag =
        setup.base == ModelKind::paper || contains(in_model, "linear_drag") || contains(in_model, "quadratic_drag");
    if (!drag && needs(setup, in_model).empty()) return "wind acts through drag, and the model has none yet";
    return std::nullopt;
  }
  // From the IMU alone a linear drag turns a wind into a constant force, which a tilt of the sensor gives as well:
  // only the quadratic law's asymmetry (upwind and downwind manoeuvres drag differently) and turns of the heading
  // tell the wind apart. So without a quadratic drag, the wind comes with one.
  std::vector<std::string> needs(const ModelSetup& setup, std::span<const std::string> in_model) const override {
    if (setup.velocity != VelocitySource::filter || setup.base == ModelKind::paper ||
        contains(in_model, "quadratic_drag"))
      return {};
    return {"quadratic_drag"};
  }
  std::vector<Parameter> parameters(const ModelSetup&) const override {
    return {{"north", "m/s", 0.0, -30.0, 30.0}, {"east", "m/s", 0.0, -30.0, 30.0}};
  }
  // Drag on v - w is not convex in w: from no wind, LM can settle in a linear-drag-like minimum. So the fit also
  // starts from a moderate breeze (4 m/s, mid-range for a small multirotor's flying weather) from each quarter.
  std::vector<std::vector<double>> more_starts(std::span<const double>) const override {
    constexpr double kBreeze = 4.0;
    return {{kBreeze, 0.0}, {-kBreeze, 0.0}, {0.0, kBreeze}, {0.0, -kBreeze}};
  }
  Eigen::Vector3d wind_ned(std::span<const double> p) const override { return {p[0], p[1], 0.0}; }
  std::string live_path(const Parameter& p) const override {
    return std::string("full.wind.") + (p.name == "north" ? "0" : "1");
  }
  void to_live(std::span<const double> v, std::span<const Parameter> p, const LiveContext& context,
               estimator::FullModelParams& live) const override {
    for (std::size_t i = 0; i < p.size(); ++i) live.wind[p[i].name == "north" ? 0 : 1] = v[i];
    // The world the wind was fitted in: the model's attitude at the first sample. The filter's heading starts at 0
    // there, which is the default.
    if (context.setup.velocity == VelocitySource::filter) return;
    if (const std::optional<Eigen::Quaterniond> q = context.first_attitude()) {
      const Eigen::Matrix3d r = q->toRotationMatrix();
      live.wind_heading = std::atan2(r(1, 0), r(0, 0));
    }
  }
};

}  // namespace

std::unique_ptr<Effect> make_wind() { return std::make_unique<Wind>(); }

}  // namespace imubridge::diagnose
