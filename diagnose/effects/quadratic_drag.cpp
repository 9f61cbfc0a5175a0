// quadratic_drag: the paper's drag -mu |v| v on each horizontal body axis, for a base model without it
// (docs/effects.md).
#include "diagnose/effects/library.hpp"

namespace imubridge::diagnose {
namespace {

class QuadraticDrag final : public Effect {
 public:
  std::string_view name() const override { return "quadratic_drag"; }
  Stages stages() const override { return {.drag = true}; }
  std::optional<std::string> why_not(const ModelSetup& setup, std::span<const std::string>) const override {
    if (setup.base == ModelKind::paper) return "eq. (14) already has the quadratic drag mu";
    return std::nullopt;
  }
  std::vector<Parameter> parameters(const ModelSetup& setup) const override {
    return per_axis(setup, "mu", "1/m", 0.0, 100.0);
  }
  void add_drag(std::span<const double> p, const ModelSetup& setup, DragLaw& law) const override {
    for (std::size_t i = 0; i < setup.axes.size(); ++i) law.mu[setup.axes[i]] += p[i];
  }
  std::string live_path(const Parameter& p) const override { return per_axis_live_path("drag_quadratic", p); }
  void to_live(std::span<const double> v, std::span<const Parameter> p, const LiveContext&,
               estimator::FullModelParams& live) const override {
    add_per_axis(v, p, live.drag_quadratic);
  }
};

}  // namespace

std::unique_ptr<Effect> make_quadratic_drag() { return std::make_unique<QuadraticDrag>(); }

}  // namespace imubridge::diagnose
