// time_offset: the accelerometer's samples lag the gyro's by tau; the model takes its inputs at t - tau
// (docs/effects.md).
#include "diagnose/effects/library.hpp"

namespace imubridge::diagnose {
namespace {

class TimeOffset final : public Effect {
 public:
  std::string_view name() const override { return "time_offset"; }
  Stages stages() const override { return {.timing = true}; }
  std::vector<Parameter> parameters(const ModelSetup&) const override { return {{"tau", "s", 0.0, -0.25, 0.25}}; }
  double time_offset(std::span<const double> p) const override { return p[0]; }
  std::string live_path(const Parameter&) const override { return "full.time_offset"; }
  void to_live(std::span<const double> v, std::span<const Parameter>, const LiveContext&,
               estimator::FullModelParams& live) const override {
    live.time_offset = v[0];
  }
};

}  // namespace

std::unique_ptr<Effect> make_time_offset() { return std::make_unique<TimeOffset>(); }

}  // namespace imubridge::diagnose
