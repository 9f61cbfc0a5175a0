// The effect library of `imubridge diagnose` (docs/effects.md): each effect's contribution on hand-made inputs, and
// the generic fit (diagnose/model.hpp) recovering effects' parameters from synthetic series built from the model.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "diagnose/effects/library.hpp"
#include "diagnose/model.hpp"
#include "diagnose/signals.hpp"
#include "estimator/constants.hpp"
#include "estimator/paper_model.hpp"

namespace imubridge::diagnose {
namespace {

using Eigen::Vector3d;
constexpr double kTwoPi = 2.0 * std::numbers::pi;
constexpr double kG = estimator::kGravity;

const Effect& effect(std::string_view name) {
  const Effect* e = find_effect(name);
  if (e == nullptr) throw std::invalid_argument("no effect " + std::string(name));
  return *e;
}

// A synthetic 20-s flight at 200 Hz: pitch and roll rates made of two sinusoids each, a smooth reference velocity,
// level attitude. The accelerometer is filled in by each test from the model it checks.
Signals synthetic_signals(double duration = 20.0) {
  estimator::ImuSeries series;
  series.reference.emplace();
  for (int k = 0; k < static_cast<int>(duration * 200); ++k) {
    const double t = k / 200.0;
    series.t.push_back(t);
    series.gyro.emplace_back(1.5 * std::sin(kTwoPi * 0.45 * t) + 0.8 * std::sin(kTwoPi * 2.3 * t),
                             2.0 * std::sin(kTwoPi * 0.7 * t) + 1.2 * std::sin(kTwoPi * 1.9 * t), 0.0);
    series.accel.emplace_back(0.0, 0.0, -kG);
    series.reference->velocity_ned.emplace_back(1.5 * std::sin(0.5 * t), 1.0 * std::cos(0.3 * t), 0.0);
    series.reference->attitude.push_back(Eigen::Quaterniond::Identity());
  }
  return prepare_signals(series);
}

ModelSetup paper_setup(const Signals& s, std::vector<int> axes = {0, 1}) {
  ModelSetup setup;
  setup.signals = &s;
  setup.axes = std::move(axes);
  return setup;
}

// Eq. (14) at the paper's geometry on both axes, from the signals' own angular acceleration and velocity.
void fill_paper_accel(Signals& s, double mu = 0.04) {
  const estimator::PaperAxisParams p{0.18, 85.0 * std::numbers::pi / 180.0, -0.01, mu};
  const auto c = estimator::paper_coefficients(p);
  for (std::size_t k = 0; k < s.size(); ++k) {
    const Vector3d& v = s.reference->velocity_body[k];
    s.accel[k].x() =
        estimator::paper_specific_force(c, {.omega = s.gyro[k].y(), .omega_dot = s.gyro_rate[k].y(), .v = -v.x()});
    s.accel[k].y() =
        estimator::paper_specific_force(c, {.omega = -s.gyro[k].x(), .omega_dot = -s.gyro_rate[k].x(), .v = -v.y()});
  }
}

// Fits `effects` on top of the paper model from the base's closed-form start and the effects' defaults.
FitOutcome fit_with(const Signals& s, const std::vector<const Effect*>& effects,
                    std::vector<double> effect_start = {}) {
  const Model base(s, paper_setup(s));
  const Range all{0, s.size()};
  const Model model(s, paper_setup(s), effects);
  std::vector<double> start = base.base_start(all);
  for (std::size_t i = start.size(); i < model.parameters().size(); ++i) start.push_back(model.parameters()[i].initial);
  for (std::size_t i = 0; i < effect_start.size(); ++i) start[base.base_size() + i] = effect_start[i];
  return fit(model, start, all);
}

// ---- contributions on hand-made inputs ----

TEST(Effects, LibraryHasEveryDocumentedEffectOnce) {
  std::vector<std::string> names;
  for (const auto& e : effect_library()) names.emplace_back(e->name());
  EXPECT_EQ(names, (std::vector<std::string>{"linear_drag", "quadratic_drag", "accel_bias", "gyro_bias", "thrust",
                                             "time_offset", "accel_scale", "accel_cross", "lever_arm_z", "vibration",
                                             "wind", "self_consistent_velocity"}));
  EXPECT_EQ(find_effect("no_such_effect"), nullptr);
}

// The model calls an effect's hooks only for the stages it declares (Effect::stages), so a hook that acts outside
// them would be silently unused, and a declared stage without a hook would mark inputs as moving for nothing.
TEST(Effects, EachEffectActsThroughTheStagesItDeclaresAndNoOthers) {
  const Signals s = synthetic_signals(1.0);
  const ModelSetup setup = paper_setup(s);
  for (const auto& e : effect_library()) {
    SCOPED_TRACE(std::string(e->name()));
    std::vector<double> p;
    for (const Parameter& parameter : e->parameters(setup)) {
      const bool bounded = std::isfinite(parameter.lower) && std::isfinite(parameter.upper);
      p.push_back(bounded ? parameter.lower + 0.37 * (parameter.upper - parameter.lower) : 0.37);
    }
    const Stages declared = e->stages();

    std::vector<Vector3d> gyro(3, Vector3d(0.1, -0.2, 0.3));
    e->adjust_gyro(p, setup, gyro);
    EXPECT_EQ(gyro[0] != Vector3d(0.1, -0.2, 0.3), declared.gyro);
    EXPECT_EQ(e->time_offset(p) != 0.0, declared.timing);
    EXPECT_EQ(!e->wind_ned(p).isZero(), declared.wind);
    DragLaw law;
    e->add_drag(p, setup, law);
    EXPECT_EQ(!law.k.isZero() || !law.mu.isZero(), declared.drag);
    std::vector<Vector3d> predicted(3, Vector3d(1.0, -2.0, -9.0));
    const std::vector<Vector3d> measured(3, Vector3d(1.5, -1.5, -9.5));
    e->adjust_sensor(p, setup, predicted, measured);
    EXPECT_EQ(predicted[0] != Vector3d(1.0, -2.0, -9.0), declared.sensor);
    // Every effect acts somewhere.
    EXPECT_TRUE(declared.gyro || declared.timing || declared.wind || declared.drag || declared.drag_in_dynamics ||
                declared.measured_thrust || declared.sensor || declared.prediction);
  }
}

TEST(Effects, DragEffectsAddTheirCoefficientsPerDiagnosedAxis) {
  const Signals s = synthetic_signals(1.0);
  DragLaw law;
  effect("linear_drag").add_drag(std::vector<double>{0.5}, paper_setup(s, {1}), law);
  EXPECT_EQ(law.k, Eigen::Vector2d(0.0, 0.5));
  ModelSetup full = paper_setup(s);
  full.base = ModelKind::full;
  effect("quadratic_drag").add_drag(std::vector<double>{0.1, 0.2}, full, law);
  EXPECT_EQ(law.mu, Eigen::Vector2d(0.1, 0.2));
  EXPECT_TRUE(effect("quadratic_drag").why_not(paper_setup(s), {}).has_value());  // eq. (14) has mu
  EXPECT_FALSE(effect("quadratic_drag").why_not(full, {}).has_value());
}

TEST(Effects, GyroBiasIsTakenOffTheAxesTheModelUses) {
  const Signals s = synthetic_signals(1.0);
  std::vector<Vector3d> gyro{Vector3d(1.0, 2.0, 3.0)};
  // The paper's pitch axis (x) uses gyro y.
  effect("gyro_bias").adjust_gyro(std::vector<double>{0.25}, paper_setup(s, {0}), gyro);
  EXPECT_EQ(gyro[0], Vector3d(1.0, 1.75, 3.0));
  ModelSetup full = paper_setup(s);
  full.base = ModelKind::full;
  effect("gyro_bias").adjust_gyro(std::vector<double>{0.1, 0.2, 0.3}, full, gyro);
  EXPECT_TRUE(gyro[0].isApprox(Vector3d(0.9, 1.55, 2.7)));
}

TEST(Effects, SensorErrorsActOnThePredictedReading) {
  const Signals s = synthetic_signals(1.0);
  std::vector<Vector3d> predicted{Vector3d(1.0, 2.0, -9.0)};
  const std::vector<Vector3d> measured{Vector3d(1.5, 2.5, -9.5)};
  effect("accel_scale").adjust_sensor(std::vector<double>{0.1, -0.2}, paper_setup(s), predicted, measured);
  EXPECT_TRUE(predicted[0].isApprox(Vector3d(1.1, 1.6, -9.0)));
  // Cross-axis: each axis reads a fraction of the other's (measured) specific force.
  effect("accel_cross").adjust_sensor(std::vector<double>{0.1, 0.2}, paper_setup(s), predicted, measured);
  EXPECT_TRUE(predicted[0].isApprox(Vector3d(1.1 + 0.1 * 2.5, 1.6 + 0.2 * 1.5, -9.0)));
}

TEST(Effects, AdditiveTermsGoOntoThePrediction) {
  const Signals s = synthetic_signals(1.0);
  const ModelSetup setup = paper_setup(s);
  ModelInputs inputs;
  inputs.gyro = {Vector3d(1.0, 2.0, 0.0)};
  inputs.gyro_rate = {Vector3d(3.0, -4.0, 0.0)};
  PredictionContext ctx{setup, inputs, {{0.2, 0.0, 0.1, 0.0}, {0.2, 0.0, -0.1, 0.0}}, {}, 0, 1};
  AxisValues prediction{{0.0}, {0.0}};
  effect("accel_bias").add_prediction(std::vector<double>{0.3, -0.4}, ctx, prediction);
  EXPECT_DOUBLE_EQ(prediction[0][0], 0.3);
  EXPECT_DOUBLE_EQ(prediction[1][0], -0.4);

  // lever_arm_z: -sin(alpha) times the z component of w_dot x r + w x (w x r), r = (r cos(beta), 0, z) for x.
  prediction = {{0.0}, {0.0}};
  effect("lever_arm_z").add_prediction(std::vector<double>{-0.15}, ctx, prediction);
  const auto lever_z = [&](const Vector3d& r) {
    const Vector3d& w = inputs.gyro[0];
    return (inputs.gyro_rate[0].cross(r) + w.cross(w.cross(r))).z();
  };
  EXPECT_NEAR(prediction[0][0], -std::sin(0.1) * lever_z(Vector3d(0.2, 0.0, -0.15)), 1e-12);
  EXPECT_NEAR(prediction[1][0], -std::sin(-0.1) * lever_z(Vector3d(0.0, 0.2, -0.15)), 1e-12);

  // vibration: a sin + b cos of the phase at the sample's time.
  prediction = {{0.0}, {0.0}};
  PredictionContext at_sample{setup, inputs, {}, {}, 37, 1};
  effect("vibration").add_prediction(std::vector<double>{12.0, 0.5, 0.25, -0.1, 0.0}, at_sample, prediction);
  const double phase = kTwoPi * 12.0 * s.t[37];
  EXPECT_NEAR(prediction[0][0], 0.5 * std::sin(phase) + 0.25 * std::cos(phase), 1e-12);
  EXPECT_NEAR(prediction[1][0], -0.1 * std::sin(phase), 1e-12);
}

TEST(Effects, StageFlagsAndApplicability) {
  const Signals s = synthetic_signals(1.0);
  ModelSetup reference = paper_setup(s), imu = paper_setup(s), full = paper_setup(s);
  imu.velocity = VelocitySource::eq12;
  full.base = ModelKind::full;
  EXPECT_DOUBLE_EQ(effect("time_offset").time_offset(std::vector<double>{0.02}), 0.02);
  EXPECT_EQ(effect("wind").wind_ned(std::vector<double>{3.0, -1.0}), Vector3d(3.0, -1.0, 0.0));
  EXPECT_TRUE(effect("thrust").stages().measured_thrust);
  EXPECT_TRUE(effect("thrust").why_not(full, {}).has_value());
  EXPECT_TRUE(effect("self_consistent_velocity").stages().drag_in_dynamics);
  EXPECT_TRUE(effect("self_consistent_velocity").why_not(reference, {}).has_value());
  EXPECT_FALSE(effect("self_consistent_velocity").why_not(imu, {}).has_value());
  // The full model has no drag until one is added: no wind, no self-consistent velocity before.
  ModelSetup full_imu = full;
  full_imu.velocity = VelocitySource::eq12;
  EXPECT_TRUE(effect("wind").why_not(full, {}).has_value());
  const std::vector<std::string> with_drag{"quadratic_drag"};
  EXPECT_FALSE(effect("wind").why_not(full, with_drag).has_value());
  EXPECT_FALSE(effect("self_consistent_velocity").why_not(full_imu, with_drag).has_value());
  // Only a thrust that varies tells an accelerometer bias from eq. (14)'s g sin(alpha).
  EXPECT_TRUE(effect("accel_bias").why_not(reference, {}).has_value());
  const std::vector<std::string> with_thrust{"thrust"};
  EXPECT_FALSE(effect("accel_bias").why_not(reference, with_thrust).has_value());
}

TEST(Effects, VibrationStartsAtTheResidualsLine) {
  const Signals s = synthetic_signals(20.0);
  const ModelSetup setup = paper_setup(s, {0});
  AxisValues residual(1);
  for (double t : s.t) residual[0].push_back(0.2 * std::sin(kTwoPi * 23.37 * t + 0.4));
  std::vector<double> p(5, 0.0);
  ASSERT_FALSE(effect("vibration").start({setup, s.t, residual}, p).has_value());
  EXPECT_NEAR(p[0], 23.37, 0.01);
  EXPECT_NEAR(std::hypot(p[1], p[2]), 0.2, 0.01);
  // Inside an ignored band there is nothing to start from.
  ModelSetup ignoring = setup;
  ignoring.ignore_bands = {{23.0, 24.0}};
  EXPECT_TRUE(effect("vibration").start({ignoring, s.t, residual}, p).has_value());
}

// ---- the model and the fit ----

TEST(Model, TheBaseModelReproducesEq14) {
  Signals s = synthetic_signals();
  fill_paper_accel(s);
  const Model model(s, paper_setup(s));
  const Range all{0, s.size()};
  const FitOutcome f = fit(model, model.base_start(all), all);
  EXPECT_LT(model.rmse(f.values, all), 1e-9);
  EXPECT_NEAR(f.values[0], 0.18, 1e-6);  // x.r
  EXPECT_NEAR(f.values[3], 0.04, 1e-6);  // x.mu
  EXPECT_FALSE(f.convergence.empty());
}

TEST(Model, AnglesComeBackInOneTurnWhateverTurnTheFitStartsIn) {
  Signals s = synthetic_signals();
  fill_paper_accel(s);
  const Model model(s, paper_setup(s));
  const Range all{0, s.size()};
  std::vector<double> start = model.base_start(all);
  start[1] += 4.0 * std::numbers::pi;  // x.beta two turns away: the same mounting to the model
  start[6] -= 2.0 * std::numbers::pi;  // y.alpha one turn the other way
  const FitOutcome f = fit(model, start, all);
  EXPECT_LT(model.rmse(f.values, all), 1e-9);
  EXPECT_NEAR(f.values[1], 85.0 * std::numbers::pi / 180.0, 1e-6);  // x.beta, in (-pi, pi]
  EXPECT_NEAR(f.values[2], -0.01, 1e-6);                            // x.alpha
  for (std::size_t i : {1, 2, 5, 6}) {
    EXPECT_GT(f.values[i], -std::numbers::pi) << model.parameters()[i].name;
    EXPECT_LE(f.values[i], std::numbers::pi) << model.parameters()[i].name;
  }
}

TEST(Model, FitRecoversLinearDrag) {
  Signals s = synthetic_signals();
  fill_paper_accel(s);
  for (std::size_t k = 0; k < s.size(); ++k)
    s.accel[k].head<2>() -= Eigen::Vector2d(0.6, 0.3).cwiseProduct(s.reference->velocity_body[k].head<2>());
  const FitOutcome f = fit_with(s, {&effect("linear_drag")});
  EXPECT_NEAR(f.values[8], 0.6, 1e-6);
  EXPECT_NEAR(f.values[9], 0.3, 1e-6);
}

TEST(Model, FitRecoversATimeOffset) {
  Signals s = synthetic_signals();
  // The accelerometer sees the motion 12 ms late: eq. (14) evaluated on inputs delayed by 12 ms.
  fill_paper_accel(s);
  const double tau = 0.012;
  std::vector<Vector3d> accel = s.accel;
  for (std::size_t k = 0; k < s.size(); ++k) {
    const double at = s.t[k] - tau;
    const std::size_t j = std::min<std::size_t>(static_cast<std::size_t>(std::max(0.0, at) * 200.0), s.size() - 2);
    const double f = std::clamp((at - s.t[j]) * 200.0, 0.0, 1.0);
    accel[k] = (1.0 - f) * s.accel[j] + f * s.accel[j + 1];
  }
  s.accel = accel;
  const FitOutcome f = fit_with(s, {&effect("time_offset")});
  EXPECT_NEAR(f.values[8], tau, 2e-4);
  EXPECT_FALSE(std::isnan(f.std_errors[8]));
}

TEST(Model, FitRecoversAVibrationFromItsStart) {
  Signals s = synthetic_signals();
  fill_paper_accel(s);
  for (std::size_t k = 0; k < s.size(); ++k) s.accel[k].x() += 0.3 * std::sin(kTwoPi * 41.3 * s.t[k]);
  const Model base(s, paper_setup(s, {0}));
  const Range all{0, s.size()};
  const FitOutcome base_fit = fit(base, base.base_start(all), all);
  const AxisValues residual = base.evaluate(base_fit.values, all).residual();
  const Model model(s, paper_setup(s, {0}), {&effect("vibration")});
  std::vector<double> start = base_fit.values;
  start.resize(model.parameters().size(), 0.0);
  ASSERT_FALSE(effect("vibration").start({model.setup(), s.t, residual}, std::span(start).subspan(4)).has_value());
  const FitOutcome f = fit(model, start, all);
  EXPECT_NEAR(f.values[4], 41.3, 1e-4);
  EXPECT_NEAR(f.values[5], 0.3, 1e-3);
  EXPECT_LT(model.rmse(f.values, all), 1e-3);
}

TEST(Model, FitIsDeterministic) {
  Signals s = synthetic_signals();
  fill_paper_accel(s);
  for (std::size_t k = 0; k < s.size(); ++k) s.accel[k].x() += 0.05 * std::sin(1.7 * k);  // not the model
  const FitOutcome a = fit_with(s, {&effect("linear_drag")});
  const FitOutcome b = fit_with(s, {&effect("linear_drag")});
  EXPECT_EQ(a.values, b.values);
  EXPECT_EQ(a.convergence, b.convergence);
}

TEST(Model, RefusesWhatCannotApply) {
  estimator::ImuSeries series;
  for (int k = 0; k < 100; ++k) {
    series.t.push_back(k * 0.005);
    series.gyro.emplace_back(0.0, 0.0, 0.0);
    series.accel.emplace_back(0.0, 0.0, -kG);
  }
  const Signals s = prepare_signals(series);
  EXPECT_THROW(Model(s, paper_setup(s)), std::invalid_argument);  // reference velocity without a reference
  ModelSetup imu = paper_setup(s);
  imu.velocity = VelocitySource::eq12;
  EXPECT_NO_THROW(Model(s, imu));
  EXPECT_THROW(Model(s, imu, {&effect("quadratic_drag")}), std::invalid_argument);
  imu.axes.clear();
  EXPECT_THROW(Model(s, imu), std::invalid_argument);
}

}  // namespace
}  // namespace imubridge::diagnose
