// self_consistent_velocity: the IMU-only velocity integrated with the identified drag in the vehicle's own
// dynamics, instead of eq. (12)'s drag-free integration that drifts (docs/effects.md). No parameter of its own: it
// uses the model's drag law, refitted with it.
#include "diagnose/effects/library.hpp"

namespace imubridge::diagnose {
namespace {

class SelfConsistentVelocity final : public Effect {
 public:
  std::string_view name() const override { return "self_consistent_velocity"; }
  Stages stages() const override { return {.drag_in_dynamics = true}; }
  std::optional<std::string> why_not(const ModelSetup& setup, std::span<const std::string> in_model) const override {
    if (setup.velocity == VelocitySource::reference) return "the velocity comes from the reference trajectory";
    if (setup.velocity == VelocitySource::filter) return "the filter's velocity has the drag in its dynamics already";
    const bool drag =
        setup.base == ModelKind::paper || contains(in_model, "linear_drag") || contains(in_model, "quadratic_drag");
    if (!drag) return "the model has no drag law to integrate yet";
    return std::nullopt;
  }
  std::vector<Parameter> parameters(const ModelSetup&) const override { return {}; }
};

}  // namespace

std::unique_ptr<Effect> make_self_consistent_velocity() { return std::make_unique<SelfConsistentVelocity>(); }

}  // namespace imubridge::diagnose
