#include "diagnose/effects/library.hpp"

namespace imubridge::diagnose {

const std::vector<std::unique_ptr<Effect>>& effect_library() {
  static const std::vector<std::unique_ptr<Effect>> library = [] {
    std::vector<std::unique_ptr<Effect>> all;
    all.push_back(make_linear_drag());
    all.push_back(make_quadratic_drag());
    all.push_back(make_accel_bias());
    all.push_back(make_gyro_bias());
    all.push_back(make_thrust());
    all.push_back(make_time_offset());
    all.push_back(make_accel_scale());
    all.push_back(make_accel_cross());
    all.push_back(make_lever_arm_z());
    all.push_back(make_vibration());
    all.push_back(make_wind());
    all.push_back(make_self_consistent_velocity());
    return all;
  }();
  return library;
}

const Effect* find_effect(std::string_view name) {
  for (const auto& effect : effect_library()) {
    if (effect->name() == name) return effect.get();
  }
  return nullptr;
}

}  // namespace imubridge::diagnose
