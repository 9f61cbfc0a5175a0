// Cost of one residual analysis as `imubridge diagnose` runs it after every step: 36,000 samples (3 min at 200 Hz, or
// 36 s at 1000 Hz) against 20 candidate signals, lags +-0.5 s. Target: well under a second.
#include <benchmark/benchmark.h>

#include <cmath>
#include <string>
#include <vector>

#include "diagnose/residual_analysis.hpp"
#include "sim/random.hpp"

namespace imubridge::diagnose {
namespace {

constexpr std::size_t kSamples = 36000;
constexpr int kCandidates = 20;

std::vector<double> noise(std::uint64_t seed, double smoothing) {
  sim::Rng rng(seed);
  std::vector<double> x(kSamples);
  double state = 0.0;
  for (double& v : x) v = state = smoothing * state + rng.normal();
  return x;
}

void BM_AnalyseResidual(benchmark::State& state) {
  const double rate = double(state.range(0));
  std::vector<double> t(kSamples);
  for (std::size_t i = 0; i < kSamples; ++i) t[i] = double(i) / rate;
  const std::vector<double> residual = noise(1, 0.3);
  std::vector<NamedSignal> candidates;
  for (int c = 0; c < kCandidates; ++c) candidates.push_back({"signal" + std::to_string(c), noise(100 + c, 0.95)});
  for (auto _ : state) benchmark::DoNotOptimize(analyse_residual(t, residual, candidates, {}));
}
BENCHMARK(BM_AnalyseResidual)->Arg(200)->Arg(1000)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime();

}  // namespace
}  // namespace imubridge::diagnose
