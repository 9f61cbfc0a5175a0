// Identification of the accelerometer model (docs/identification.md) and the evidence in docs/results.md: the
// paper's scenario is simulated with the paper's (r, beta, alpha, mu) and both methods must give them back; the
// drag-velocity estimator is judged against the simulator's true velocity.
#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <random>
#include <string>

#include "estimator/constants.hpp"
#include "identification/identify.hpp"
#include "replay/session_series.hpp"
#include "sim/imu_series.hpp"
#include "sim/scenario.hpp"
#include "store/store.hpp"

namespace imubridge::estimator {
namespace {

using sim::kPaperAlpha;
using sim::kPaperBeta;
using sim::kPaperMu;
using sim::kPaperR;

constexpr double kDeg = kPi / 180.0;
const TimeWindow kTrain{0.0, 33.0}, kValidation{33.0, 60.0};  // the paper's split of the 60-s flight

// A simulated flight (60 s at 200 Hz, seed 1): the samples with their truth, and the measurements as the estimator
// reads them, with the truth as the reference trajectory. Simulated once per scenario and shared by the tests.
struct Flight {
  std::vector<sim::SimSample> samples;
  ImuSeries series;
  Eigen::Matrix3d sensor_from_body;
};

const Flight& flight(const std::string& scenario) {
  static std::map<std::string, Flight> cache;
  auto [it, added] = cache.try_emplace(scenario);
  Flight& f = it->second;
  if (added) {
    const sim::SimConfig config = sim::make_scenario(scenario, 1);
    f.samples = sim::simulate(config);
    f.sensor_from_body = config.imu.pose.sensor_from_body;
    f.series = sim::imu_series(f.samples);
  }
  return f;
}

// RMS over the samples in `w` of a per-sample quantity.
template <typename Value>
double rms_in(const Flight& f, const TimeWindow& w, Value value) {
  double sum = 0.0;
  int n = 0;
  for (std::size_t k = 0; k < f.samples.size(); ++k) {
    if (f.samples[k].time_s < w.start || !(f.samples[k].time_s < w.end)) continue;
    const double v = value(k);
    sum += v * v;
    ++n;
  }
  return std::sqrt(sum / n);
}

// The accelerometer noise actually in the x channel: measured minus what a perfect sensor would read.
double accel_x_noise(const Flight& f, const TimeWindow& w) {
  return rms_in(f, w, [&](std::size_t k) { return f.samples[k].measured.accel.x() - f.samples[k].ideal.accel.x(); });
}

// The true angular acceleration about the sensor's y axis: the pitch model's omega_dot.
double true_pitch_rate(const Flight& f, std::size_t k) {
  return (f.sensor_from_body * f.samples[k].truth.omega_dot).y();
}

void expect_paper_parameters(const PaperAxisParams& p) {
  EXPECT_NEAR(p.r, kPaperR, 0.02 * kPaperR);
  EXPECT_NEAR(p.beta, kPaperBeta, 1.0 * kDeg);
  EXPECT_NEAR(p.alpha, kPaperAlpha, 0.1 * kDeg);
  EXPECT_NEAR(p.mu, kPaperMu, 0.05 * kPaperMu);
}

void expect_same_optimum(const PaperAxisParams& ga, const ModelParams& lm) {
  const std::map<std::string, double>& se = lm.identification.std_errors;
  EXPECT_LT(std::abs(ga.r - lm.paper_x.r), 0.1 * se.at("paper.x.r"));
  EXPECT_LT(std::abs(ga.beta - lm.paper_x.beta), 0.1 * se.at("paper.x.beta"));
  EXPECT_LT(std::abs(ga.alpha - lm.paper_x.alpha), 0.1 * se.at("paper.x.alpha"));
  EXPECT_LT(std::abs(ga.mu - lm.paper_x.mu), 0.1 * se.at("paper.x.mu"));
}

IdentifyOptions options(Method method, VelocitySource velocity) {
  IdentifyOptions o;
  o.method = method;
  o.velocity = velocity;
  return o;
}

// ---- the pieces ----

TEST(PaperFit, LinearFitIsExactOnExactData) {
  // Eq. (14) evaluated at known parameters on varied signals, without noise: the closed form must return them.
  const PaperAxisParams truth{kPaperR, kPaperBeta, kPaperAlpha, kPaperMu};
  std::vector<PaperSample> samples;
  for (int k = 0; k < 500; ++k) {
    const double t = 0.01 * k;
    PaperSample s{
        .t = t, .omega = 2.0 * std::sin(3.0 * t), .omega_dot = 6.0 * std::cos(3.0 * t), .v = 1.5 * std::sin(0.7 * t)};
    s.f = paper_specific_force(paper_coefficients(truth), s);
    samples.push_back(s);
  }
  const PaperAxisParams fit = paper_linear_fit(samples);
  EXPECT_NEAR(fit.r, truth.r, 1e-12);
  EXPECT_NEAR(fit.beta, truth.beta, 1e-10);
  EXPECT_NEAR(fit.alpha, truth.alpha, 1e-12);
  EXPECT_NEAR(fit.mu, truth.mu, 1e-12);
  // LM from far away lands on the same point.
  const PaperFit lm = fit_paper_lm(samples, {0.05, 0.3, 0.05, 0.2});
  EXPECT_TRUE(lm.report.converged) << lm.report.message;
  EXPECT_NEAR(lm.params.r, truth.r, 1e-9);
  EXPECT_NEAR(lm.params.beta, truth.beta, 1e-8);
  EXPECT_NEAR(lm.params.alpha, truth.alpha, 1e-9);
  EXPECT_NEAR(lm.params.mu, truth.mu, 1e-9);
  EXPECT_LT(lm.report.final_objective, 1e-9);
}

TEST(PaperFit, StandardErrorsMatchTheScatterOverNoiseRealisations) {
  // 200 fits of the same signals with fresh white noise: the spread of each estimate must be what the covariance
  // (scaled by the residual variance) says. 200 draws pin a standard deviation to about 5 %; 15 % is three of those.
  const PaperAxisParams truth{kPaperR, kPaperBeta, kPaperAlpha, kPaperMu};
  std::mt19937_64 engine(7);
  const auto normal = [&engine] {  // Box-Muller on our own uniform draws, repeatable everywhere
    const double u1 = (static_cast<double>(engine() >> 11) + 1.0) * 0x1.0p-53;
    const double u2 = static_cast<double>(engine() >> 11) * 0x1.0p-53;
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * kPi * u2);
  };
  constexpr int kRuns = 200;
  Eigen::Matrix<double, 4, kRuns> estimates;
  Eigen::Vector4d reported = Eigen::Vector4d::Zero();
  for (int run = 0; run < kRuns; ++run) {
    std::vector<PaperSample> samples;
    for (int k = 0; k < 400; ++k) {
      const double t = 0.01 * k;
      PaperSample s{
          .t = t, .omega = 2.0 * std::sin(3.0 * t), .omega_dot = 6.0 * std::cos(3.0 * t), .v = 1.5 * std::sin(0.7 * t)};
      s.f = paper_specific_force(paper_coefficients(truth), s) + 0.05 * normal();
      samples.push_back(s);
    }
    const PaperFit fit = fit_paper_lm(samples, paper_linear_fit(samples));
    estimates.col(run) << fit.params.r, fit.params.beta, fit.params.alpha, fit.params.mu;
    const Uncertainty u = paper_uncertainty(samples, fit.params);
    ASSERT_TRUE(u.failure.empty()) << u.failure;
    reported += u.std_error / kRuns;
  }
  const Eigen::Vector4d mean = estimates.rowwise().mean();
  const Eigen::Vector4d scatter = ((estimates.colwise() - mean).array().square().rowwise().sum() / (kRuns - 1)).sqrt();
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(scatter[i] / reported[i], 1.0, 0.15) << "parameter " << i;
}

TEST(SmoothedDerivative, ExactForCubicsAtTheEndsAndUnderJitter) {
  // A least-squares cubic reproduces a cubic, so its slope is exact wherever the window holds four samples.
  std::vector<double> t;
  std::vector<Eigen::Vector3d> x;
  for (int k = 0; k < 300; ++k) {
    const double tk = 0.005 * k + 0.0013 * std::sin(1.7 * k);  // jittered, still increasing
    t.push_back(tk);
    x.emplace_back(1.0 + 2.0 * tk - 3.0 * tk * tk + 0.5 * tk * tk * tk, 4.0 * tk, -tk * tk);
  }
  const std::vector<Eigen::Vector3d> d = smoothed_derivative(t, x, 0.0315);
  for (std::size_t k = 0; k < t.size(); ++k) {
    const Eigen::Vector3d exact(2.0 - 6.0 * t[k] + 1.5 * t[k] * t[k], 4.0, -2.0 * t[k]);
    EXPECT_LT((d[k] - exact).norm(), 1e-9) << "sample " << k;
  }
}

TEST(SmoothedDerivative, AveragesNoiseFarBetterThanTheCentralDifference) {
  // On white noise sigma at period h the central difference gives sigma / (sqrt(2) h) = 0.71 sigma / h. The cubic
  // fit over +-6 samples must do at least three times better (its weights give 0.19 sigma / h).
  std::mt19937_64 engine(3);
  std::vector<double> t;
  std::vector<Eigen::Vector3d> x;
  for (int k = 0; k < 4000; ++k) {
    t.push_back(0.005 * k);
    x.emplace_back(static_cast<double>(engine() >> 11) * 0x1.0p-53 - 0.5, 0.0, 0.0);  // uniform: sigma = 1 / sqrt(12)
  }
  const std::vector<Eigen::Vector3d> d = smoothed_derivative(t, x, 0.0315);
  double sum = 0.0;
  for (std::size_t k = 10; k + 10 < t.size(); ++k) sum += d[k].x() * d[k].x();
  const double gain = std::sqrt(sum / (t.size() - 20)) * 0.005 * std::sqrt(12.0);  // in units of sigma / h
  EXPECT_LT(gain, 0.71 / 3.0);
  EXPECT_THROW(smoothed_derivative(t, x, 0.0), std::invalid_argument);
  EXPECT_THROW(smoothed_derivative(std::span(t).first(3), x, 0.03), std::invalid_argument);
}

TEST(Windows, DefaultIsThePapersSplitClippedToTheData) {
  std::vector<double> t;
  for (int k = 0; k < 12000; ++k) t.push_back(0.005 * k);  // 60 s: the last sample's period ends at 60 s
  const Windows w = resolve_windows(t, std::nullopt, std::nullopt);
  EXPECT_EQ(w.train, (TimeWindow{0.0, 33.0}));
  EXPECT_EQ(w.validate.start, 33.0);
  EXPECT_NEAR(w.validate.end, 60.0, 1e-9);
  const Windows custom = resolve_windows(t, TimeWindow{-5.0, 20.0}, std::nullopt);  // validation follows training
  EXPECT_EQ(custom.train, (TimeWindow{0.0, 20.0}));
  EXPECT_EQ(custom.validate.start, 20.0);
  EXPECT_THROW(resolve_windows(t, TimeWindow{70.0, 80.0}, std::nullopt), std::invalid_argument);
  EXPECT_THROW(resolve_windows(std::span(t).first(20 * 200), std::nullopt, std::nullopt), std::invalid_argument);
  EXPECT_THROW(resolve_windows({}, std::nullopt, std::nullopt), std::invalid_argument);
}

TEST(Windows, ParsesSecondsAndRejectsTheRest) {
  EXPECT_EQ(parse_window("0:33"), (TimeWindow{0.0, 33.0}));
  EXPECT_EQ(parse_window("12.5:40.25"), (TimeWindow{12.5, 40.25}));
  EXPECT_EQ(parse_window("33:").end, std::numeric_limits<double>::infinity());
  for (const char* bad : {"", "33", ":10", "10:5", "5:5", "a:b", "1:2:3", "nan:4", "1 :2"})
    EXPECT_THROW(parse_window(bad), std::invalid_argument) << bad;
}

TEST(Windows, PercentagesAreFractionsOfTheDataSpan) {
  const std::vector<double> t{10.0, 11.0, 12.0, 13.0, 14.0};      // data end 15 s: the span is [10, 15)
  EXPECT_EQ(parse_window("0:40%", t), (TimeWindow{10.0, 12.0}));  // one "%" makes both ends percentages
  EXPECT_EQ(parse_window("0%:40%", t), (TimeWindow{10.0, 12.0}));
  EXPECT_EQ(parse_window("40%:", t), (TimeWindow{12.0, 15.0}));  // an open end is 100 %, the span's end
  EXPECT_EQ(parse_window("40%:", TimeWindow{100.0, 200.0}), (TimeWindow{140.0, 200.0}));  // a flight's, not the log's
  EXPECT_EQ(parse_window("20%:100%", t), (TimeWindow{11.0, 15.0}));
  EXPECT_EQ(parse_window("20:60%", TimeWindow{100.0, 200.0}), (TimeWindow{120.0, 160.0}));  // of any span
  for (const char* bad : {"50%:40%", "-1%:20%", "0:101%", "%:10", "10%%:20%"})
    EXPECT_THROW(parse_window(bad, t), std::invalid_argument) << bad;
  EXPECT_THROW(parse_window("0:40%"), std::invalid_argument);  // a percentage without the data
}

TEST(FullResidual, VanishesOnIdealDataAtTheTrueParameters) {
  // A perfect sensor at the paper's pose, the true angular acceleration and air velocity: the 3-D model at the
  // simulator's parameters leaves nothing but rounding.
  const Flight& f = flight("paper");
  FullModelParams truth;
  truth.lever_arm = kPaperR * Eigen::Vector3d(std::cos(kPaperBeta), 0.0, -std::sin(kPaperBeta));
  truth.mounting = {0.0, kPaperAlpha, 0.0};
  truth.drag_quadratic = {kPaperMu, kPaperMu};
  double worst = 0.0;
  for (std::size_t k = 0; k < f.samples.size(); k += 7) {
    const sim::SimSample& s = f.samples[k];
    const FullSample sample{s.time_s, s.ideal.gyro, f.sensor_from_body * s.truth.omega_dot, s.ideal.accel,
                            s.truth.air_velocity_body.head<2>()};
    worst = std::max(worst, full_rmse(truth, std::span(&sample, 1)).maxCoeff());
  }
  EXPECT_LT(worst, 1e-9);
}

TEST(FullFromPaper, PlacesTheImuWhereThePaperGeometrySays) {
  // The simulator's pose for the paper's (r, beta, alpha), seen by the pitch axis, and its roll-axis counterpart
  // (docs/estimator.md): at r (0, cos b, -sin b) with b = 90 deg, i.e. the same height, no tilt about x.
  const PaperAxisParams pitch{kPaperR, kPaperBeta, kPaperAlpha, kPaperMu};
  const PaperAxisParams roll{kPaperR * std::sin(kPaperBeta), kPi / 2, 0.0, 0.02};
  const FullModelParams p = full_from_paper(pitch, roll);
  const sim::ImuPose pose = sim::ImuPose::paper(kPaperR, kPaperBeta, kPaperAlpha);
  EXPECT_LT((p.lever_arm - pose.position_m).norm(), 1e-12);
  const Eigen::Matrix3d imu_to_body = Eigen::AngleAxisd(p.mounting.norm(), p.mounting.normalized()).toRotationMatrix();
  EXPECT_LT((imu_to_body.transpose() - pose.sensor_from_body).norm(), 1e-12);
  EXPECT_EQ(p.drag_quadratic, Eigen::Vector2d(kPaperMu, 0.02));
  EXPECT_EQ(p.drag_linear, Eigen::Vector2d::Zero());
}

// ---- evidence on the paper's scenario ----

TEST(PaperScenario, LmRecoversThePapersParameters) {
  const IdentifyResult r = identify(flight("paper").series, options(Method::lm, VelocitySource::reference));
  expect_paper_parameters(r.params.paper_x);
  // The roll axis sees the same IMU from the side: at r sin(beta) = 0.178 m straight above (beta = 90 deg), no tilt.
  EXPECT_NEAR(r.params.paper_y.r, kPaperR * std::sin(kPaperBeta), 0.02 * kPaperR);
  EXPECT_NEAR(r.params.paper_y.beta, kPi / 2, 1.0 * kDeg);
  EXPECT_NEAR(r.params.paper_y.alpha, 0.0, 0.1 * kDeg);
  const Identification& id = r.params.identification;
  EXPECT_EQ(id.method, "lm");
  EXPECT_EQ(id.fit_windows, std::vector{kTrain});
  EXPECT_EQ(id.validation_windows.size(), 1u);
  for (const char* key : {"paper.x.r", "paper.x.beta", "paper.x.alpha", "paper.x.mu"})
    EXPECT_GT(id.std_errors.at(key), 0.0);
  // The standard errors are small enough that the truth sits within a few of them, except for the known beta bias.
  EXPECT_LT(std::abs(r.params.paper_x.r - kPaperR), 4.0 * id.std_errors.at("paper.x.r"));
  EXPECT_LT(std::abs(r.params.paper_x.alpha - kPaperAlpha), 4.0 * id.std_errors.at("paper.x.alpha"));
}

TEST(PaperScenario, GaRecoversThePapersParametersAtLmsOptimum) {
  const Flight& f = flight("paper");
  const IdentifyResult ga = identify(f.series, options(Method::ga, VelocitySource::reference));
  const IdentifyResult lm = identify(f.series, options(Method::lm, VelocitySource::reference));
  expect_paper_parameters(ga.params.paper_x);
  // Same optimum: LM's is the exact minimum of OF; the GA's must be a tenth of a standard error from it or closer,
  // a difference the data cannot resolve.
  expect_same_optimum(ga.params.paper_x, lm.params);
  EXPECT_GE(ga.fits[0].fit_objective, lm.fits[0].fit_objective * (1.0 - 1e-12));
  // The convergence curve (the paper's Fig. 12) ends at the objective of the parameters returned.
  EXPECT_EQ(ga.fits[0].convergence.size(), 301u);
  EXPECT_DOUBLE_EQ(ga.fits[0].convergence.back(), ga.fits[0].fit_objective);
  EXPECT_EQ(ga.params.identification.method, "ga");
  EXPECT_EQ(ga.params.identification.seed, 1u);
}

TEST(PaperScenario, GaIsBitForBitRepeatableAndOtherSeedsReachTheSameOptimum) {
  // 20 s of training halve the GA's work; the optimum compared against is LM's on the same 20 s.
  const Flight& f = flight("paper");
  IdentifyOptions o = options(Method::ga, VelocitySource::reference);
  o.train = TimeWindow{0.0, 20.0};
  o.ga.seed = 11;
  const IdentifyResult a = identify(f.series, o);
  const IdentifyResult b = identify(f.series, o);
  EXPECT_EQ(a.params.paper_x, b.params.paper_x);  // operator== on doubles: bit for bit
  EXPECT_EQ(a.params.paper_y, b.params.paper_y);
  EXPECT_EQ(a.fits[0].convergence, b.fits[0].convergence);
  o.ga.seed = 12;
  const IdentifyResult c = identify(f.series, o);
  EXPECT_NE(a.fits[0].convergence, c.fits[0].convergence);  // another search...
  o.method = Method::lm;
  const IdentifyResult lm = identify(f.series, o);
  expect_same_optimum(a.params.paper_x, lm.params);  // ...to the same place
  expect_same_optimum(c.params.paper_x, lm.params);
}

TEST(PaperScenario, GivenTheTrueAngularAccelerationTheResidualIsTheAccelerometerNoise) {
  // With omega_dot exact, what eq. (14) cannot explain is the accelerometer's own noise (plus eq. 14's dropped
  // terms, docs/model.md): the validation RMSE must be within 10 % of the noise actually in the x channel.
  const Flight& f = flight("paper");
  std::vector<PaperSample> samples =
      prepare_paper(f.series, PaperAxis::pitch, VelocitySource::reference, IdentifyOptions{}.derivative_half_window);
  for (std::size_t k = 0; k < samples.size(); ++k) samples[k].omega_dot = true_pitch_rate(f, k);
  const PaperFit fit = fit_paper_lm(select(samples, kTrain), paper_linear_fit(select(samples, kTrain)));
  expect_paper_parameters(fit.params);
  const double noise = accel_x_noise(f, kValidation);
  const double validation = rmse(fit.params, select(samples, kValidation));
  EXPECT_LT(validation, 1.1 * noise);
  EXPECT_GT(validation, 0.95 * noise);  // a fit cannot explain the noise away
}

TEST(PaperScenario, ValidationRmseIsTheNoiseOfTheMeasuredInputs) {
  // From the gyro, omega_dot carries the gyro's differentiated noise (no filter can remove all of it: the flight's
  // omega_dot has content up to 20 Hz). The residual is then the accelerometer noise plus r sin(beta) times that
  // omega_dot error; the validation RMSE must be within 10 % of this floor, measured on the same samples.
  const Flight& f = flight("paper");
  const IdentifyResult r = identify(f.series, options(Method::lm, VelocitySource::reference));
  const std::vector<PaperSample> samples =
      prepare_paper(f.series, PaperAxis::pitch, VelocitySource::reference, IdentifyOptions{}.derivative_half_window);
  const double rate_error =
      rms_in(f, kValidation, [&](std::size_t k) { return samples[k].omega_dot - true_pitch_rate(f, k); });
  const double noise = accel_x_noise(f, kValidation);
  const double floor = std::hypot(noise, kPaperR * std::sin(kPaperBeta) * rate_error);
  const double validation = r.params.identification.rmse.at("paper.x.validation");
  EXPECT_LT(validation, 1.1 * floor);
  EXPECT_GT(validation, 0.9 * floor);
  EXPECT_GT(validation, noise);
}

TEST(PaperScenario, Eq12VelocityDriftsAndBiasesMuLow) {
  // Eq. (12) integrates the pitch but leaves drag out of the vehicle's dynamics, so its velocity drifts from the
  // true one; the drag regressed on it comes out low. The geometry (r, beta, alpha) does not depend on it.
  const Flight& f = flight("paper");
  const IdentifyResult r = identify(f.series, options(Method::lm, VelocitySource::eq12));
  EXPECT_NEAR(r.params.paper_x.r, kPaperR, 0.02 * kPaperR);
  EXPECT_NEAR(r.params.paper_x.beta, kPaperBeta, 1.0 * kDeg);
  EXPECT_NEAR(r.params.paper_x.alpha, kPaperAlpha, 0.1 * kDeg);
  EXPECT_LT(r.params.paper_x.mu, 0.95 * kPaperMu);
  const double h = IdentifyOptions{}.derivative_half_window;
  const auto eq12 = prepare_paper(f.series, PaperAxis::pitch, VelocitySource::eq12, h);
  const auto truth = prepare_paper(f.series, PaperAxis::pitch, VelocitySource::reference, h);
  const double speed = rms_in(f, kTrain, [&](std::size_t k) { return truth[k].v; });
  const double drift = rms_in(f, kTrain, [&](std::size_t k) { return eq12[k].v - truth[k].v; });
  EXPECT_GT(drift, 0.25 * speed);
  EXPECT_GT(std::abs(eq12.back().v - truth.back().v), 2.0 * drift);  // and it grows without bound
}

// ---- the 3-D model ----

TEST(FullModelIdentification, LmRecoversLeverArmMountingAndDrag) {
  // 15 s of training keep the test short. The bias is held: see the next test for why it must be on this flight.
  const Flight& f = flight("paper");
  IdentifyOptions o = options(Method::lm, VelocitySource::reference);
  o.train = TimeWindow{0.0, 15.0};
  const IdentifyResult paper = identify(f.series, o);
  o.model = ModelKind::full;
  o.hold.blocks[static_cast<int>(FullBlock::accel_bias)] = true;
  const IdentifyResult r = identify(f.series, o);
  const FullModelParams& p = r.params.full;
  const Eigen::Vector3d lever = kPaperR * Eigen::Vector3d(std::cos(kPaperBeta), 0.0, -std::sin(kPaperBeta));
  EXPECT_LT((p.lever_arm - lever).norm(), 0.003);
  EXPECT_NEAR(p.mounting.x(), 0.0, 0.1 * kDeg);
  EXPECT_NEAR(p.mounting.y(), kPaperAlpha, 0.1 * kDeg);
  EXPECT_NEAR(p.drag_quadratic.x(), kPaperMu, 0.1 * kPaperMu);
  EXPECT_EQ(p.accel_bias, Eigen::Vector3d::Zero());
  // It predicts the held-out data at least as well as eq. (14), whose dropped terms it keeps.
  EXPECT_LT(r.params.identification.rmse.at("full.x.validation"),
            1.01 * paper.params.identification.rmse.at("paper.x.validation"));
}

TEST(FullModelIdentification, CorrelationShowsBiasAndTiltCannotBeToldApartOnThisFlight) {
  // The thrust stays near g, so a tilt alpha of the sensor's x axis adds g sin(alpha), nearly a constant: the x
  // bias does the same. The correlation matrix must say so.
  const Flight& f = flight("paper");
  IdentifyOptions o = options(Method::lm, VelocitySource::reference);
  o.model = ModelKind::full;
  o.train = TimeWindow{0.0, 15.0};
  const IdentifyResult r = identify(f.series, o);
  const Uncertainty& u = r.fits[0].uncertainty;
  ASSERT_TRUE(u.failure.empty()) << u.failure;
  const auto index = [&](const std::string& name) {
    return static_cast<Eigen::Index>(std::find(u.names.begin(), u.names.end(), name) - u.names.begin());
  };
  EXPECT_LT(u.correlation(index("accel_bias.0"), index("mounting.1")), -0.95);
}

// ---- the drag-velocity estimator ----

TEST(VelocityEvaluation, BeatsTheRawInversionEq12AndStandingStill) {
  // IMU at the mass centre ("center", the paper's section VIII) and far from it ("paper"), parameters identified on
  // the same flight: the filtered velocity must be well ahead of every alternative.
  for (const std::string scenario : {"center", "paper"}) {
    const Flight& f = flight(scenario);
    const IdentifyResult r = identify(f.series, options(Method::lm, VelocitySource::reference));
    const VelocityEvaluation e = evaluate_velocity(f.series, r.params.full);
    EXPECT_GT(e.samples, f.samples.size() - 10);
    EXPECT_LT(e.estimator.horizontal, e.zero.horizontal) << scenario;
    EXPECT_LT(e.estimator.horizontal, 0.5 * e.inversion.horizontal) << scenario;
    EXPECT_LT(e.estimator.horizontal, 0.5 * e.eq12.horizontal) << scenario;
    EXPECT_EQ(e.counters.rejected_non_finite + e.counters.rejected_out_of_range + e.counters.rejected_time, 0u);
  }
}

TEST(VelocityEvaluation, NeedsAReferenceAndDrag) {
  const Flight& f = flight("center");
  ImuSeries without = f.series;
  without.reference.reset();
  FullModelParams drag;
  drag.drag_quadratic = {kPaperMu, kPaperMu};
  EXPECT_THROW(evaluate_velocity(without, drag), std::invalid_argument);
  EXPECT_THROW(evaluate_velocity(f.series, FullModelParams{}), std::invalid_argument);
  EXPECT_THROW(evaluate_velocity(f.series, drag, TimeWindow{100.0, 200.0}), std::invalid_argument);
  const VelocityEvaluation part = evaluate_velocity(f.series, drag, TimeWindow{10.0, 20.0});
  EXPECT_EQ(part.samples, 2000u);
}

// A model that reads drag on x only (the X500's loop, docs/results.md) is scored as the estimator flies it: the
// x velocity from the drag, rest on y, so y's error is exactly "not moving"'s, as the anchor scores an axis without
// drag. It was refused ("needs drag on both axes"), and a user of such a model was told nothing.
TEST(VelocityEvaluation, AnAxisWithoutDragIsScoredAsRest) {
  const Flight& f = flight("center");
  FullModelParams x_only;
  x_only.drag_quadratic = {kPaperMu, 0.0};
  const VelocityEvaluation e = evaluate_velocity(f.series, x_only);
  EXPECT_EQ(e.estimator.axis.y(), e.zero.axis.y());
  EXPECT_GT(e.zero.axis.y(), 0.0);
  EXPECT_LT(e.estimator.axis.x(), 0.5 * e.zero.axis.x());
  EXPECT_LT(e.estimator.horizontal, e.zero.horizontal);
}

// ---- reading a session ----

constexpr double kYawRate = 0.4;  // rad/s: the reference turns about z at a constant rate

class SessionSeriesTest : public ::testing::Test {
 protected:
  std::filesystem::path path_ =
      std::filesystem::temp_directory_path() / ("imubridge_session_series_" + std::to_string(::getpid()) + ".db");
  void TearDown() override {
    for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(path_.string() + suffix);
  }

  static protocol::Sample sample(std::int64_t link, std::int64_t device_us, std::int64_t recv_ns, double value) {
    protocol::Sample s;
    s.link_id = link;
    s.device_time_us = device_us;
    s.recv_mono_ns = recv_ns;
    s.accel = {value, -value, -9.8};
    s.gyro = {0.0, 0.0, kYawRate};  // the turn the reference's attitude makes
    return s;
  }
};

constexpr std::int64_t kMono0 = 7'000'000'000;  // the session's monotonic clock at the first pose

Eigen::Vector3d reference_velocity(double t) { return {1.0 + 0.5 * t, -2.0 * t, 0.1}; }

TEST_F(SessionSeriesTest, TimesByTheDeviceClockAndInterpolatesTheReferenceAtReceiveTime) {
  std::int64_t session = 0;
  {
    store::Store store(path_);
    session = store.begin_session({.kind = "test"});
    const std::int64_t link = store.add_link(session, "imu0", "imubridge", "test");
    const std::int64_t sparse = store.add_link(session, "imu1", "imubridge", "test");
    // Poses at 100 Hz from kMono0: velocity linear in time, attitude turning at a constant rate, so that linear
    // interpolation and slerp are exact between them.
    for (int j = 0; j <= 100; ++j) {
      const double t = 0.01 * j;
      const Eigen::Quaterniond q(Eigen::AngleAxisd(kYawRate * t, Eigen::Vector3d::UnitZ()));
      const Eigen::Vector3d v = reference_velocity(t);
      store.append_reference(session, {.t_ns = kMono0 + 10'000'000 * j,
                                       .position = {0.0, 0.0, 0.0},
                                       .quat_wxyz = {q.w(), q.x(), q.y(), q.z()},
                                       .velocity = std::array{v.x(), v.y(), v.z()}});
    }
    // 200 Hz samples, device clock starting at 3 s, received 2.5 ms into each period; the first arrives before the
    // first pose. One sample repeats a device time and one is NaN: both are dropped and counted.
    for (int k = 0; k < 190; ++k) {
      const std::int64_t recv = kMono0 - 5'000'000 + 5'000'000 * k + 2'500'000;
      store.append_sample(session, sample(link, 3'000'000 + 5000 * k, recv, k));
      if (k == 50) store.append_sample(session, sample(link, 3'000'000 + 5000 * k, recv, -1.0));
      if (k == 60) store.append_sample(session, sample(link, 3'000'000 + 5000 * k + 1, recv, std::nan("")));
    }
    for (int k = 0; k < 5; ++k) store.append_sample(session, sample(sparse, 5000 * k, kMono0 + 5'000'000 * k, 0.0));
    store.commit();
  }
  const store::Store store(path_, {.read_only = true});
  // Declared FRD: these samples' made-up specific force would make `auto` turn them x-up.
  const replay::SessionSeries plain = replay::read_session_series(store, session, {.imu_axes = "frd"});
  EXPECT_EQ(plain.link_id, 1);  // the link with the most samples
  EXPECT_EQ(plain.counts.samples, 192u);
  EXPECT_EQ(plain.counts.time_not_increasing, 1u);
  EXPECT_EQ(plain.counts.non_finite, 1u);
  ASSERT_EQ(plain.series.size(), 190u);
  EXPECT_FALSE(plain.series.reference);
  EXPECT_DOUBLE_EQ(plain.series.t[0], 0.0);
  EXPECT_DOUBLE_EQ(plain.series.t[189], 189 * 0.005);
  EXPECT_EQ(plain.series.accel[51].x(), 51.0);  // the repeat after sample 50 is gone

  const replay::SessionSeries with =
      replay::read_session_series(store, session, {.reference = replay::ReferenceUse::required, .imu_axes = "frd"});
  EXPECT_EQ(with.counts.outside_reference, 1u);  // the first sample, received before the first pose
  EXPECT_EQ(with.counts.reference_rows, 101u);
  ASSERT_EQ(with.series.size(), 189u);
  ASSERT_TRUE(with.series.reference);
  EXPECT_DOUBLE_EQ(with.series.t[0], 0.005);  // session time still counts from the link's first sample
  for (std::size_t k = 0; k < with.series.size(); ++k) {
    const double received = 0.005 * static_cast<double>(k) + 0.0025;  // seconds after the first pose
    EXPECT_LT((with.series.reference->velocity_ned[k] - reference_velocity(received)).norm(), 1e-12) << k;
    const Eigen::Quaterniond expected(Eigen::AngleAxisd(kYawRate * received, Eigen::Vector3d::UnitZ()));
    EXPECT_LT(with.series.reference->attitude[k].angularDistance(expected), 1e-9) << k;
  }
  EXPECT_FALSE(validate(with.series));

  const replay::SessionSeries other = replay::read_session_series(store, session, {.link = 2});
  EXPECT_EQ(other.series.size(), 5u);

  // One flight, one identity, however it is read (here the reference's span drops the first sample, and other axes
  // turn every one): a model fitted with the reference knows its own flight when replayed without it.
  EXPECT_EQ(with.flight, plain.flight);
  EXPECT_EQ(replay::read_session_series(store, session, {.imu_axes = "flu"}).flight, plain.flight);
  EXPECT_NE(other.flight, plain.flight);
}

TEST_F(SessionSeriesTest, DerivesVelocityFromPositionsAndNamesWhatIsMissing) {
  std::int64_t session = 0, bare = 0;
  {
    store::Store store(path_);
    session = store.begin_session({.kind = "test"});
    bare = store.begin_session({.kind = "test"});
    store.begin_session({.kind = "empty"});
    const std::int64_t link = store.add_link(session, "imu0", "imubridge", "test");
    const std::int64_t bare_link = store.add_link(bare, "imu0", "imubridge", "test");
    // Positions quadratic in time: the central difference gives their velocity exactly between the ends.
    for (int j = 0; j <= 50; ++j) {
      const double t = 0.02 * j;
      store.append_reference(
          session,
          {.t_ns = kMono0 + 20'000'000 * j, .position = {3.0 * t, t * t, -1.5}, .quat_wxyz = {1.0, 0.0, 0.0, 0.0}});
    }
    for (int k = 0; k < 200; ++k) {
      store.append_sample(session, sample(link, 5000 * k, kMono0 + 5'000'000 * k, 0.0));
      store.append_sample(bare, sample(bare_link, 5000 * k, kMono0 + 5'000'000 * k, 0.0));
    }
    store.commit();
  }
  const store::Store store(path_, {.read_only = true});
  const replay::SessionSeries s =
      replay::read_session_series(store, session, {.reference = replay::ReferenceUse::required});
  ASSERT_EQ(s.series.size(), 200u);
  for (std::size_t k = 4; k < 196; ++k) {  // away from the one-sided ends
    const double t = 0.005 * static_cast<double>(k);
    EXPECT_LT((s.series.reference->velocity_ned[k] - Eigen::Vector3d(3.0, 2.0 * t, 0.0)).norm(), 1e-9) << k;
  }
  EXPECT_THROW(replay::read_session_series(store, bare, {.reference = replay::ReferenceUse::required}),
               std::invalid_argument);
  // when_present (diagnose's default): the trajectory where the session has one, none where it has not.
  const auto when_present = [&](std::int64_t id) {
    return replay::read_session_series(store, id, {.reference = replay::ReferenceUse::when_present});
  };
  ASSERT_TRUE(when_present(session).series.reference);
  EXPECT_EQ(when_present(session).series.reference->velocity_ned, s.series.reference->velocity_ned);
  EXPECT_FALSE(when_present(bare).series.reference);
  EXPECT_EQ(when_present(bare).series.size(), 200u);
  EXPECT_THROW(replay::read_session_series(store, 3), std::invalid_argument);                     // no samples
  EXPECT_THROW(replay::read_session_series(store, 99), std::invalid_argument);                    // no such session
  EXPECT_THROW(replay::read_session_series(store, session, {.link = 2}), std::invalid_argument);  // not its link
}

}  // namespace
}  // namespace imubridge::estimator
