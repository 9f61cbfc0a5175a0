#pragma once
// The library of effects (docs/effects.md), in one place: every effect `imubridge diagnose` may add, one file each
// in diagnose/effects/.
#include <memory>
#include <string_view>
#include <vector>

#include "diagnose/effects/effect.hpp"

namespace imubridge::diagnose {

std::unique_ptr<Effect> make_linear_drag();
std::unique_ptr<Effect> make_quadratic_drag();
std::unique_ptr<Effect> make_accel_bias();
std::unique_ptr<Effect> make_gyro_bias();
std::unique_ptr<Effect> make_thrust();
std::unique_ptr<Effect> make_time_offset();
std::unique_ptr<Effect> make_accel_scale();
std::unique_ptr<Effect> make_accel_cross();
std::unique_ptr<Effect> make_lever_arm_z();
std::unique_ptr<Effect> make_vibration();
std::unique_ptr<Effect> make_wind();
std::unique_ptr<Effect> make_self_consistent_velocity();

// Every effect, in a fixed order (the order candidates are tried and reported in when they tie).
const std::vector<std::unique_ptr<Effect>>& effect_library();
// The library's effect of that name, or nullptr.
const Effect* find_effect(std::string_view name);

}  // namespace imubridge::diagnose
