// thrust: the thrust specific force T from the measured body-z reading instead of the paper's U1 = g
// (docs/effects.md). No parameter: it replaces an assumption with a measurement.
#include "diagnose/effects/library.hpp"

namespace imubridge::diagnose {
namespace {

class Thrust final : public Effect {
 public:
  std::string_view name() const override { return "thrust"; }
  Stages stages() const override { return {.measured_thrust = true}; }
  std::optional<std::string> why_not(const ModelSetup& setup, std::span<const std::string>) const override {
    if (setup.base == ModelKind::full)
      return "the full model's residual is in body axes, where the thrust has no horizontal component";
    return std::nullopt;
  }
  std::vector<Parameter> parameters(const ModelSetup&) const override { return {}; }
};

}  // namespace

std::unique_ptr<Effect> make_thrust() { return std::make_unique<Thrust>(); }

}  // namespace imubridge::diagnose
