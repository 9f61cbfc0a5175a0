// Cost per sample of the estimator's models (what an identification pays per objective evaluation) and of the live
// drag-velocity estimator (target: well under 1 us per sample on one core).
#include <benchmark/benchmark.h>

#include <cmath>
#include <random>
#include <vector>

#include "estimator/constants.hpp"
#include "estimator/differentiator.hpp"
#include "estimator/drag_velocity.hpp"
#include "estimator/full_model.hpp"
#include "estimator/lever_arm_compensation.hpp"
#include "estimator/paper_model.hpp"

namespace imubridge::estimator {
namespace {

constexpr int kSamples = 4096;
constexpr double kH = 0.005;

FullModelParams params() {
  FullModelParams p;
  p.lever_arm = {0.12, -0.04, -0.06};
  p.mounting = {0.01, -0.02, 0.05};
  p.drag_linear = {0.35, 0.4};
  p.drag_quadratic = {0.04, 0.05};
  p.accel_bias = {0.05, -0.03, 0.1};
  return p;
}

// Noisy hovering-and-swaying samples: the numbers only have to be realistic enough to exercise every branch.
std::vector<ImuSample> samples() {
  std::mt19937 rng(1);
  std::normal_distribution<double> noise(0.0, 0.05);
  std::vector<ImuSample> out(kSamples);
  for (int k = 0; k < kSamples; ++k) {
    const double t = k * kH;
    out[k].t = t;
    out[k].gyro = {0.3 * std::sin(1.7 * t) + noise(rng), 0.4 * std::cos(2.1 * t) + noise(rng), 0.2 + noise(rng)};
    out[k].accel = {-0.4 * std::sin(0.5 * t) + noise(rng), 0.3 * std::cos(0.4 * t) + noise(rng),
                    -kGravity + noise(rng)};
  }
  return out;
}

std::vector<PaperSample> paper_samples() {
  ImuSeries series;
  for (const ImuSample& s : samples()) {
    series.t.push_back(s.t);
    series.gyro.push_back(s.gyro);
    series.accel.push_back(s.accel);
  }
  return prepare_paper_axis(series, PaperAxis::pitch);
}

void BM_PaperObjective(benchmark::State& state) {
  const auto data = paper_samples();
  PaperAxisParams p{.r = 0.179, .beta = 1.4856, .alpha = -0.0052, .mu = 0.0386};
  for (auto _ : state) {
    p.mu += 1e-12;  // a new candidate each time, as in a GA generation
    benchmark::DoNotOptimize(objective(p, data));
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(data.size()));
}
BENCHMARK(BM_PaperObjective);

void BM_FullModelPredict(benchmark::State& state) {
  const FullModelParams p = params();
  const auto data = samples();
  std::size_t k = 0;
  for (auto _ : state) {
    const ImuSample& s = data[k++ % data.size()];
    benchmark::DoNotOptimize(predict_specific_force(
        p, {.gyro = s.gyro, .gyro_rate = s.accel, .velocity = s.accel.head<2>(), .thrust = kGravity}));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_FullModelPredict);

void BM_LeverArmCompensation(benchmark::State& state) {
  const LeverArmCompensator compensator(params());
  const auto data = samples();
  std::size_t k = 0;
  for (auto _ : state) {
    const ImuSample& s = data[k++ % data.size()];
    benchmark::DoNotOptimize(compensator.compensate(s.accel, s.gyro, s.accel));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_LeverArmCompensation);

void BM_CausalDifferentiator(benchmark::State& state) {
  CausalDifferentiator differentiator(static_cast<int>(state.range(0)));
  const auto data = samples();
  std::size_t k = 0;
  for (auto _ : state) {
    const ImuSample& s = data[k % data.size()];
    benchmark::DoNotOptimize(differentiator.update(static_cast<double>(k++) * kH, s.gyro));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_CausalDifferentiator)->Arg(5)->Arg(15);

// The model a diagnosis can end with: every effect the live estimator runs switched on.
FullModelParams params_with_every_live_effect() {
  FullModelParams p = params();
  p.accel_scale = {0.01, -0.02, 0.0};
  p.accel_cross(0, 1) = 0.01;
  p.accel_cross(1, 0) = -0.01;
  p.gyro_bias = {0.01, -0.005, 0.002};
  p.time_offset = 0.02;
  p.wind = {2.0, -1.0};
  p.wind_heading = 0.3;
  return p;
}

// Arg 0: the rigid body and drag; arg 1: every live effect as well.
void BM_DragVelocityEstimatorUpdate(benchmark::State& state) {
  DragVelocityEstimator estimator(state.range(0) ? params_with_every_live_effect() : params(), DragVelocityConfig{});
  auto data = samples();
  std::size_t k = 0;
  for (auto _ : state) {
    ImuSample s = data[k % data.size()];
    s.t = static_cast<double>(k++) * kH;  // time keeps increasing across laps of the data
    benchmark::DoNotOptimize(estimator.update(s));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_DragVelocityEstimatorUpdate)->Arg(0)->Arg(1);

}  // namespace
}  // namespace imubridge::estimator
