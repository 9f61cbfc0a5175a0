// identify and diagnose on the real EuRoC MH_01 flight, as docs/results.md runs them: the 3-D model, trained on the
// first 40 % of the flight (found from the rotors' vibration) and validated on the rest, with the reference's
// velocity and from the IMU alone (the filter error method); diagnose compares below 10 Hz. Wall time on all cores.
// And the session's reading from the store that comes before identify's fit.
// The flight is read from IMUBRIDGE_EUROC_DIR, default ../shared/data/real/euroc_mh01 beside the repository; without
// it the benchmarks say so and skip.
#include <benchmark/benchmark.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>

#include "diagnose/filter_identification.hpp"
#include "diagnose/search.hpp"
#include "identification/flight_span.hpp"
#include "identification/identify.hpp"
#include "replay/session_series.hpp"
#include "importers/euroc_import.hpp"
#include "scratch_dir.hpp"
#include "store/store.hpp"

namespace imubridge::bench {
namespace {

std::filesystem::path euroc_dir() {
  if (const char* dir = std::getenv("IMUBRIDGE_EUROC_DIR")) return dir;
  return std::filesystem::path(IMUBRIDGE_SOURCE_DIR) / ".." / "shared" / "data" / "real" / "euroc_mh01";
}

// The flight, imported once (its store kept for the reading benchmark), with its windows.
struct RealFlight {
  estimator::ImuSeries series;
  estimator::TimeWindow train, validate;
  std::filesystem::path database;
  std::int64_t session = 0;
};

const std::optional<RealFlight>& real_flight() {
  static const ScratchDir scratch;
  static const std::optional<RealFlight> flight = []() -> std::optional<RealFlight> {
    const std::filesystem::path dir = euroc_dir();
    if (!std::filesystem::exists(dir / "mav0" / "imu0" / "data.csv")) return std::nullopt;
    store::Store store(scratch.database());
    importers::EurocImportOptions options;
    options.dir = dir;
    options.reference = importers::ReferenceFile{dir / "MH_01_easy.txt", importers::ReferenceFormat::tum};
    const auto imported = importers::import_euroc(store, options);
    RealFlight out;
    out.database = scratch.database();
    out.session = imported.session;
    out.series =
        replay::read_session_series(store, imported.session, {.reference = replay::ReferenceUse::when_present})
            .series;
    const auto span = estimator::detect_flight(out.series);
    if (!span) return std::nullopt;
    out.train = estimator::parse_window("0:40%", span->window);
    out.validate = estimator::parse_window("40%:", span->window);
    return out;
  }();
  return flight;
}

bool skip_without_flight(benchmark::State& state) {
  if (real_flight()) return false;
  state.SkipWithError(("no EuRoC MH_01 flight at " + euroc_dir().string() + " (set IMUBRIDGE_EUROC_DIR)").c_str());
  return true;
}

// The session read as identify reads it before fitting: samples and reference from a read-only store, the
// reference's delay estimated (docs/performance.md, "Identification on a real flight").
void ReadSession(benchmark::State& state) {
  if (skip_without_flight(state)) return;
  const store::Store store(real_flight()->database, {.read_only = true});
  const replay::SessionSeriesOptions options{.reference = replay::ReferenceUse::when_present,
                                               .estimate_reference_delay = true};
  for (auto _ : state) benchmark::DoNotOptimize(replay::read_session_series(store, real_flight()->session, options));
}

void Identify(benchmark::State& state, estimator::VelocitySource velocity, bool hold_bias) {
  if (skip_without_flight(state)) return;
  estimator::IdentifyOptions options;
  options.model = estimator::ModelKind::full;
  options.velocity = velocity;
  options.train = real_flight()->train;
  options.validate = real_flight()->validate;
  options.hold.blocks[static_cast<int>(estimator::FullBlock::accel_bias)] = hold_bias;
  for (auto _ : state) {
    benchmark::DoNotOptimize(velocity == estimator::VelocitySource::filter
                                 ? diagnose::identify_by_filter_error(real_flight()->series, options)
                                 : estimator::identify(real_flight()->series, options));
  }
}

void Diagnose(benchmark::State& state, diagnose::VelocitySource velocity) {
  if (skip_without_flight(state)) return;
  diagnose::DiagnoseOptions options;
  options.model = diagnose::ModelKind::full;
  options.velocity = velocity;
  options.train = real_flight()->train;
  options.validate = real_flight()->validate;
  options.lowpass_hz = 10.0;
  for (auto _ : state) benchmark::DoNotOptimize(diagnose::run_diagnosis(real_flight()->series, options));
}

BENCHMARK(ReadSession)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(5);
BENCHMARK_CAPTURE(Identify, FullReferenceBiasHeld, estimator::VelocitySource::reference, true)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3);
BENCHMARK_CAPTURE(Identify, FullReference, estimator::VelocitySource::reference, false)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3);
BENCHMARK_CAPTURE(Identify, FullImuAloneBiasHeld, estimator::VelocitySource::filter, true)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3);
BENCHMARK_CAPTURE(Identify, FullImuAlone, estimator::VelocitySource::filter, false)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3);
BENCHMARK_CAPTURE(Diagnose, FullReference, diagnose::VelocitySource::reference)
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);
BENCHMARK_CAPTURE(Diagnose, FullImuAlone, diagnose::VelocitySource::filter)
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);

}  // namespace
}  // namespace imubridge::bench
