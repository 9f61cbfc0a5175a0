// A diagnosed model as the live estimator runs it (diagnose/live_model.hpp): each effect's live form is its own
// (Effect::live_path, Effect::to_live), and one the live estimator cannot run makes the PARAMS.json refused.
#include "diagnose/live_model.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>
#include <vector>

#include "diagnose/effects/library.hpp"
#include "diagnose/model.hpp"
#include "diagnose/signals.hpp"
#include "estimator/constants.hpp"
#include "estimator/params.hpp"

namespace imubridge::diagnose {
namespace {

// 10 s at 200 Hz with a reference whose attitude is turned `yaw` about down: enough for a model to be built on.
Signals signals_with_yaw(double yaw) {
  estimator::ImuSeries series;
  series.reference.emplace();
  for (int k = 0; k < 2000; ++k) {
    const double t = k / 200.0;
    series.t.push_back(t);
    series.gyro.emplace_back(std::sin(t), std::cos(0.7 * t), 0.0);
    series.accel.emplace_back(0.0, 0.0, -estimator::kGravity);
    series.reference->velocity_ned.emplace_back(std::sin(0.5 * t), std::cos(0.3 * t), 0.0);
    series.reference->attitude.emplace_back(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()));
  }
  return prepare_signals(series);
}

// A model with vibration, which the live estimator cannot run, is written with the reason beside it, and refused
// with it when run, replay or evaluate read the file; the estimator keeps no list of diagnose's effects.
TEST(LiveModel, AnEffectTheLiveEstimatorCannotRunIsRefusedWhenTheFileIsRead) {
  const Signals signals = signals_with_yaw(0.0);
  ModelSetup setup;
  setup.signals = &signals;
  const Effect& vibration = *find_effect("vibration");
  ASSERT_TRUE(vibration.live_refusal());
  const Model model(signals, setup, {find_effect("linear_drag"), &vibration});
  std::vector<double> p(model.parameters().size(), 0.1);
  const estimator::ModelParams live = live_params(model, p, {});
  EXPECT_EQ(live.effects, (std::vector<std::string>{"linear_drag", "vibration"}));
  ASSERT_EQ(live.not_live.size(), 1u);
  EXPECT_EQ(live.not_live.at("vibration"), *vibration.live_refusal());
  try {
    (void)estimator::parse_params(nlohmann::json(live).dump(), "PARAMS.json");
    ADD_FAILURE() << "a model with vibration was read";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("vibration is measurement noise"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(find_effect("linear_drag")->live_refusal());
  const Model flyable(signals, setup, {find_effect("linear_drag")});
  const std::vector<double> q(flyable.parameters().size(), 0.1);
  EXPECT_TRUE(live_params(flyable, q, {}).not_live.empty());
}

// Every effect with a live form, fitted to distinct values on the full base: each value lands where that effect's
// own live form puts it, and its standard error under the path it names.
TEST(LiveModel, EachEffectPutsItsValuesWhereItsLiveFormSays) {
  const Signals signals = signals_with_yaw(0.6);
  ModelSetup setup;
  setup.base = ModelKind::full;
  setup.signals = &signals;
  std::vector<const Effect*> effects;
  for (const char* name : {"linear_drag", "quadratic_drag", "accel_bias", "gyro_bias", "time_offset", "accel_scale",
                           "accel_cross", "wind"})
    effects.push_back(find_effect(name));
  const Model model(signals, setup, effects);

  std::vector<double> p(model.parameters().size());
  for (std::size_t i = 0; i < p.size(); ++i) p[i] = 0.01 * static_cast<double>(i + 1);
  p[3] = p[4] = p[5] = 0.0;  // no mounting: the bias is the same in body and IMU axes
  const std::vector<double> std_errors(p.size(), 0.5);
  const estimator::ModelParams live = live_params(model, p, std_errors);
  const std::vector<std::string> paths = parameter_paths(model);

  // The value at each named parameter, by effect and parameter name.
  const auto value = [&](std::string_view effect, std::string_view parameter) {
    for (std::size_t e = 0; e < effects.size(); ++e) {
      if (effects[e]->name() != effect) continue;
      for (std::size_t i = model.effect_offset(e); i < model.effect_offset(e) + model.effect_size(e); ++i) {
        if (model.parameters()[i].name == parameter) return p[i];
      }
    }
    ADD_FAILURE() << effect << "." << parameter << " is not in the model";
    return std::nan("");
  };
  const estimator::FullModelParams& f = live.full;
  EXPECT_DOUBLE_EQ(f.drag_linear.x(), value("linear_drag", "k.x"));
  EXPECT_DOUBLE_EQ(f.drag_linear.y(), value("linear_drag", "k.y"));
  EXPECT_DOUBLE_EQ(f.drag_quadratic.x(), value("quadratic_drag", "mu.x"));
  EXPECT_DOUBLE_EQ(f.drag_quadratic.y(), value("quadratic_drag", "mu.y"));
  EXPECT_DOUBLE_EQ(f.accel_bias.x(), value("accel_bias", "bias.x"));
  EXPECT_DOUBLE_EQ(f.accel_bias.y(), value("accel_bias", "bias.y"));
  EXPECT_DOUBLE_EQ(f.gyro_bias.x(), value("gyro_bias", "bias.x"));
  EXPECT_DOUBLE_EQ(f.time_offset, value("time_offset", "tau"));
  EXPECT_DOUBLE_EQ(f.accel_scale.x(), value("accel_scale", "scale.x"));
  EXPECT_DOUBLE_EQ(f.accel_cross(0, 1), value("accel_cross", "cross.xy"));
  EXPECT_DOUBLE_EQ(f.wind.x(), value("wind", "north"));
  EXPECT_DOUBLE_EQ(f.wind.y(), value("wind", "east"));
  // The wind's world is the reference's heading at the first sample.
  EXPECT_NEAR(f.wind_heading, 0.6, 1e-9);
  EXPECT_EQ(live.effects.size(), effects.size());

  for (const char* path :
       {"full.drag_linear.0", "full.drag_quadratic.1", "full.accel_bias.0", "full.gyro_bias.0", "full.time_offset",
        "full.accel_scale.0", "full.accel_cross.01", "full.wind.0", "full.wind.1"}) {
    EXPECT_NE(std::find(paths.begin(), paths.end(), path), paths.end()) << path;
    EXPECT_EQ(live.identification.std_errors.count(path), 1u) << path;
  }
}

// An effect the estimator does not run keeps its parameters under its own name, and adds nothing live.
TEST(LiveModel, AnEffectWithoutALiveFormIsKeptUnderItsOwnName) {
  const Signals signals = signals_with_yaw(0.0);
  ModelSetup setup;
  setup.signals = &signals;
  const Model model(signals, setup, {find_effect("lever_arm_z")});
  std::vector<double> p(model.parameters().size(), 0.1);
  const std::vector<double> std_errors(p.size(), 0.5);
  const estimator::ModelParams live = live_params(model, p, std_errors);
  EXPECT_EQ(parameter_paths(model).back(), "effects.lever_arm_z.z");
  EXPECT_EQ(live.identification.std_errors.count("effects.lever_arm_z.z"), 1u);
  EXPECT_EQ(live.full.lever_arm, estimator::full_from_paper(live.paper_x, live.paper_y).lever_arm);
}

// The bias is found in the residual's frame, the body's; live it is in IMU axes: R_bs^T b.
TEST(LiveModel, AnAccelerometerBiasGoesLiveInImuAxes) {
  const Signals signals = signals_with_yaw(0.0);
  ModelSetup setup;
  setup.base = ModelKind::full;
  setup.signals = &signals;
  const Model model(signals, setup, {find_effect("accel_bias")});
  std::vector<double> p(model.parameters().size(), 0.0);
  p[5] = std::numbers::pi / 2;      // mounted turned 90 degrees about z
  p[model.effect_offset(0)] = 0.3;  // body x
  const estimator::ModelParams live = live_params(model, p);
  const Eigen::Vector3d imu_bias = rotation_matrix(live.full.mounting).transpose() * Eigen::Vector3d(0.3, 0.0, 0.0);
  EXPECT_TRUE(live.full.accel_bias.isApprox(imu_bias, 1e-12)) << live.full.accel_bias.transpose();
  EXPECT_GT(std::abs(live.full.accel_bias.y()), 0.29);  // turned: the body's x is the IMU's y
}

}  // namespace
}  // namespace imubridge::diagnose
