// linear_drag: rotor (momentum) drag -k v on each horizontal body axis (docs/effects.md).
#include "diagnose/effects/library.hpp"

namespace imubridge::diagnose {
namespace {

class LinearDrag final : public Effect {
 public:
  std::string_view name() const override { return "linear_drag"; }
  Stages stages() const override { return {.drag = true}; }
  std::vector<Parameter> parameters(const ModelSetup& setup) const override {
    return per_axis(setup, "k", "1/s", 0.0, 100.0);
  }
  void add_drag(std::span<const double> p, const ModelSetup& setup, DragLaw& law) const override {
    for (std::size_t i = 0; i < setup.axes.size(); ++i) law.k[setup.axes[i]] += p[i];
  }
  std::string live_path(const Parameter& p) const override { return per_axis_live_path("drag_linear", p); }
  void to_live(std::span<const double> v, std::span<const Parameter> p, const LiveContext&,
               estimator::FullModelParams& live) const override {
    add_per_axis(v, p, live.drag_linear);
  }
};

}  // namespace

std::unique_ptr<Effect> make_linear_drag() { return std::make_unique<LinearDrag>(); }

}  // namespace imubridge::diagnose
