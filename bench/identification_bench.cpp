// Identification cost on the paper's split: 33 s of the simulated paper flight at 1 kHz (33 000 samples per axis),
// as `imubridge sim --rate 1000` records it. LM against the paper's GA, and the pieces each one pays for.
#include <benchmark/benchmark.h>

#include <vector>

#include "identification/identify.hpp"
#include "sim/imu_series.hpp"
#include "sim/scenario.hpp"

namespace imubridge::estimator {
namespace {

constexpr double kRateHz = 1000.0;
const TimeWindow kTrain{0.0, 33.0};

// 40 s, so that the validation window after the 33 s of training is not empty.
const ImuSeries& series() {
  static const ImuSeries s = [] {
    sim::SimConfig config = sim::make_scenario("paper", 1, 40.0);
    config.imu.rate_hz = kRateHz;
    return sim::imu_series(sim::simulate(config));
  }();
  return s;
}

const std::vector<PaperSample>& pitch_samples() {
  static const std::vector<PaperSample> s =
      prepare_paper(series(), PaperAxis::pitch, VelocitySource::reference, IdentifyOptions{}.derivative_half_window);
  return s;
}

// The whole command's work, both paper axes: preparation, the method, standard errors, RMSEs.
void BM_IdentifyPaper(benchmark::State& state, Method method) {
  IdentifyOptions o;
  o.method = method;
  o.velocity = VelocitySource::reference;
  o.train = kTrain;
  for (auto _ : state) benchmark::DoNotOptimize(identify(series(), o));
}
BENCHMARK_CAPTURE(BM_IdentifyPaper, lm, Method::lm)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_IdentifyPaper, ga, Method::ga)->Unit(benchmark::kMillisecond);

// One axis, the optimiser alone.
void BM_PaperLm(benchmark::State& state) {
  const auto fit = select(pitch_samples(), kTrain);
  for (auto _ : state) benchmark::DoNotOptimize(fit_paper_lm(fit, paper_linear_fit(fit)));
}
BENCHMARK(BM_PaperLm)->Unit(benchmark::kMillisecond);

void BM_PaperGa(benchmark::State& state) {
  const auto fit = select(pitch_samples(), kTrain);
  const auto of = [fit](std::span<const double> g) { return objective({g[0], g[1], g[2], g[3]}, fit); };
  for (auto _ : state) benchmark::DoNotOptimize(minimize_ga(of, paper_bounds(), GaOptions{}));
}
BENCHMARK(BM_PaperGa)->Unit(benchmark::kMillisecond);

void BM_PaperUncertainty(benchmark::State& state) {
  const auto fit = select(pitch_samples(), kTrain);
  const PaperAxisParams p = paper_linear_fit(fit);
  for (auto _ : state) benchmark::DoNotOptimize(paper_uncertainty(fit, p));
}
BENCHMARK(BM_PaperUncertainty)->Unit(benchmark::kMillisecond);

void BM_PreparePaperAxis(benchmark::State& state) {
  for (auto _ : state) {
    benchmark::DoNotOptimize(
        prepare_paper(series(), PaperAxis::pitch, VelocitySource::reference, IdentifyOptions{}.derivative_half_window));
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(series().size()));
}
BENCHMARK(BM_PreparePaperAxis)->Unit(benchmark::kMillisecond);

// The 3-D model by LM (12 free parameters, the bias's z held): far costlier per iteration and per sample.
void BM_FullLm(benchmark::State& state) {
  static const std::vector<FullSample> samples =
      prepare_full(series(), VelocitySource::reference, IdentifyOptions{}.derivative_half_window);
  const auto fit = select(samples, kTrain);
  for (auto _ : state) benchmark::DoNotOptimize(fit_full_lm(fit, FullModelParams{}));
}
BENCHMARK(BM_FullLm)->Unit(benchmark::kSecond)->Iterations(1);

}  // namespace
}  // namespace imubridge::estimator
