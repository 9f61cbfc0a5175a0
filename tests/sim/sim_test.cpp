// The simulator against the physics it claims (docs/model.md, the paper's eq. 1-14) and the effects it offers.
// Truth is checked independently where possible: specific force from numerically differentiated velocities, the
// IMU's acceleration from its twice-differentiated position, effects from their statistical signature.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <bit>
#include <cmath>
#include <complex>
#include <cstdint>
#include <functional>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

#include "sim/effects.hpp"
#include "sim/flight.hpp"
#include "sim/quadrotor.hpp"
#include "sim/scenario.hpp"
#include "sim/simulator.hpp"
#include "sim/trajectory.hpp"

namespace imubridge::sim {
namespace {

using Eigen::Vector3d;
using Samples = std::vector<SimSample>;

const Vector3d kDown = Vector3d::UnitZ();

Samples run(std::string_view scenario, std::uint64_t seed, double duration_s, std::vector<std::string> effects = {},
            double rate_hz = 200.0) {
  SimConfig config = make_scenario(scenario, seed, duration_s, effects);
  config.imu.rate_hz = rate_hz;
  return simulate(config);
}

double mean_of(const Samples& samples, const std::function<double(const SimSample&)>& f) {
  double sum = 0;
  for (const SimSample& s : samples) sum += f(s);
  return sum / static_cast<double>(samples.size());
}

double max_of(const Samples& samples, const std::function<double(const SimSample&)>& f) {
  double m = -INFINITY;
  for (const SimSample& s : samples) m = std::max(m, f(s));
  return m;
}

double stddev_of(const Samples& samples, const std::function<double(const SimSample&)>& f) {
  const double mean = mean_of(samples, f);
  return std::sqrt(mean_of(samples, [&](const SimSample& s) { return std::pow(f(s) - mean, 2); }));
}

// Amplitude of the sinusoid at `hz` in the series f(sample): one DFT bin.
double amplitude_at(const Samples& samples, double hz, const std::function<double(const SimSample&)>& f) {
  std::complex<double> sum = 0;
  for (const SimSample& s : samples) sum += f(s) * std::polar(1.0, -2 * std::numbers::pi * hz * s.time_s);
  return 2 * std::abs(sum) / static_cast<double>(samples.size());
}

// Every field of every sample, as bytes (field by field: struct padding is not output).
std::vector<std::uint8_t> bytes_of(const Samples& samples) {
  std::vector<std::uint8_t> out;
  const auto put = [&](const auto& x) {
    const auto* p = reinterpret_cast<const std::uint8_t*>(&x);
    out.insert(out.end(), p, p + sizeof x);
  };
  for (const SimSample& s : samples) {
    const TrueState& t = s.truth;
    put(s.index), put(s.time_s), put(t.position_ned), put(t.velocity_ned), put(t.velocity_body);
    put(t.air_velocity_body), put(t.attitude.coeffs()), put(t.euler), put(t.omega), put(t.omega_dot);
    put(t.specific_force), put(t.rotor_speed);
    for (const ImuReading* r : {&s.ideal, &s.measured}) put(r->accel), put(r->gyro), put(r->mag), put(r->temperature_c);
    put(s.raw.accel), put(s.raw.gyro), put(s.raw.mag), put(s.raw.temperature);
  }
  return out;
}

// Specific force at the mass centre from central differences of the true NED velocity: f = R^T (a - g).
Vector3d differentiated_specific_force(const Samples& v, std::size_t i) {
  const double h = v[i + 1].time_s - v[i].time_s;
  const Vector3d a = (v[i + 1].truth.velocity_ned - v[i - 1].truth.velocity_ned) / (2 * h);
  return v[i].truth.attitude.conjugate() * (a - kGravity * kDown);
}

// --- Determinism -------------------------------------------------------------------------------------------------

TEST(SimDeterminism, SameInputsGiveIdenticalBytes) {
  const std::vector<std::string> effects{"vibration=40,0.2", "time_offset=0.01", "wind=1,-0.5"};
  const auto first = bytes_of(run("paper", 7, 8.0, effects));
  const auto second = bytes_of(run("paper", 7, 8.0, effects));
  ASSERT_FALSE(first.empty());
  EXPECT_EQ(first, second);
}

TEST(SimDeterminism, DifferentSeedChangesFlightAndNoise) {
  const Samples a = run("paper", 7, 8.0), b = run("paper", 8, 8.0);
  ASSERT_EQ(a.size(), b.size());
  EXPECT_NE(bytes_of(a), bytes_of(b));
  // The seed drives the flight plan: the attitudes part ways once manoeuvres start.
  EXPECT_GT(max_of(a, [&](const SimSample& s) { return std::abs(s.truth.euler.y() - b[s.index].truth.euler.y()); }),
            0.05);
  // ... and the noise, already while both still hover identically before the first manoeuvre.
  EXPECT_EQ(a[10].truth.position_ned, b[10].truth.position_ned);
  EXPECT_NE(a[10].measured.accel, b[10].measured.accel);
}

TEST(SimDeterminism, FlightDoesNotDependOnImuRateOrPose) {
  const Samples slow = run("paper", 3, 5.0, {}, 200.0);
  const Samples fast = run("paper", 3, 5.0, {}, 1000.0);
  const Samples center = run("center", 3, 5.0, {}, 200.0);
  ASSERT_EQ(fast.size(), 5 * slow.size());
  for (std::size_t i = 0; i < slow.size(); ++i) {
    ASSERT_EQ(slow[i].truth.position_ned, fast[5 * i].truth.position_ned) << "sample " << i;
    ASSERT_EQ(slow[i].truth.attitude.coeffs(), fast[5 * i].truth.attitude.coeffs()) << "sample " << i;
    ASSERT_EQ(slow[i].truth.omega, center[i].truth.omega) << "sample " << i;
  }
}

// --- Vehicle conventions (eq. 1-3 in FRD axes) ---------------------------------------------------------------------

TEST(SimQuadrotor, RotorsTurnTheBodyTheWayEquationTwoSays) {
  const QuadrotorParams p;
  const Quadrotor quad(p, {});
  const double w = p.hover_rotor_speed(), dw = 50;
  const auto accel_with = [&](Eigen::Vector4d rotors) {
    RigidState s = quad.hover_at(Vector3d::Zero());
    s.rotor_speed = rotors;
    return quad.angular_acceleration(s);
  };
  const double diff = std::pow(w + dw, 2) - w * w;
  // Front rotor faster: nose up (+pitch); left rotor faster: right side down (+roll).
  EXPECT_NEAR(accel_with({w + dw, w, w, w}).y(), p.arm_m * p.thrust_factor * diff / p.inertia_kgm2.y(), 1e-9);
  EXPECT_NEAR(accel_with({w, w, w, w + dw}).x(), p.arm_m * p.thrust_factor * diff / p.inertia_kgm2.x(), 1e-9);
  // Front and rear faster: their reaction torque yaws the nose right (U4's sign).
  EXPECT_NEAR(accel_with({w + dw, w, w + dw, w}).z(), 2 * p.drag_factor * diff / p.inertia_kgm2.z(), 1e-9);
  EXPECT_NEAR(quad.specific_force(quad.hover_at(Vector3d::Zero())).z(), -kGravity, 1e-12);
}

TEST(SimQuadrotor, GyroscopicTermCouplesRollRateIntoPitch) {
  QuadrotorParams p;
  p.inertia_kgm2 = {3e-3, 3e-3, 6e-3};  // equal Ixx, Iyy: no rigid-body coupling, only the rotors' momentum
  const Quadrotor quad(p, {});
  RigidState s = quad.hover_at(Vector3d::Zero());
  const double w = p.hover_rotor_speed(), dw = 40, roll_rate = 2.0;
  s.rotor_speed = {w, w + dw, w, w + dw};  // net rotor spin Omega = 2 dw along +z_b (eq. 3)
  s.omega = {roll_rate, 0, 0};
  // Angular momentum balance: I w_dot = -w x (J_TP Omega z_b), so q_dot = +J_TP Omega p / I_yy.
  EXPECT_NEAR(quad.angular_acceleration(s).y(), p.rotor_inertia_kgm2 * 2 * dw * roll_rate / p.inertia_kgm2.y(), 1e-9);
}

// --- Flight -------------------------------------------------------------------------------------------------------

TEST(SimFlight, HoverIsSteady) {
  const Samples v = run("hover", 1, 10.0);
  for (const SimSample& s : v) {
    ASSERT_LT((s.truth.position_ned - Vector3d(0, 0, -1.5)).norm(), 1e-6) << "t=" << s.time_s;
    ASSERT_LT(s.truth.omega.norm(), 1e-6) << "t=" << s.time_s;
    ASSERT_LT((s.ideal.accel + kGravity * kDown).norm(), 1e-6) << "t=" << s.time_s;
  }
  // The measured mean is the ideal one: noise averages out, quantisation (0.019 m/s^2 steps) is dithered by it.
  EXPECT_NEAR(mean_of(v, [](const SimSample& s) { return s.measured.accel.x(); }), 0.0, 0.005);
  EXPECT_NEAR(mean_of(v, [](const SimSample& s) { return s.measured.accel.z(); }), -kGravity, 0.005);
}

TEST(SimFlight, PaperScenarioIsAgileAndStaysNearTheStart) {
  const Samples v = run("paper", 11, 60.0);
  ASSERT_EQ(v.size(), 12000u);
  const double peak_rate = max_of(v, [](const SimSample& s) { return std::abs(s.truth.omega.y()); });
  const double peak_accel = max_of(v, [](const SimSample& s) { return std::abs(s.truth.omega_dot.y()); });
  EXPECT_GT(peak_rate, 2.0);
  EXPECT_LT(peak_rate, 8.0);
  EXPECT_GT(peak_accel, 20.0);
  EXPECT_LT(peak_accel, 150.0);
  EXPECT_GT(kPaperR * peak_accel, 3.0) << "lever-arm term r * w_dot of several m/s^2";
  EXPECT_GT(max_of(v, [](const SimSample& s) { return std::abs(s.truth.omega.x()); }), 1.0) << "some roll too";
  EXPECT_GT(max_of(v, [](const SimSample& s) { return s.truth.velocity_ned.head<2>().norm(); }), 1.0)
      << "fast enough for drag to show";
  EXPECT_LT(max_of(v, [](const SimSample& s) { return s.truth.position_ned.head<2>().norm(); }), 5.0);
  EXPECT_LT(max_of(v, [](const SimSample& s) { return std::abs(s.truth.position_ned.z() + 1.5); }), 0.2);
}

// The `climb` scenario is the agile flight with climbs and descents: the same roll and pitch plan, the altitude
// following its reference and back at the start height when the plan ends, and a thrust (body-z specific force at
// the mass centre) that varies far more than the altitude hold's g / (cos phi cos theta) makes it.
TEST(SimFlight, ClimbsMakeTheThrustVaryAndTheAltitudeReturns) {
  const SimConfig climb_config = make_scenario("climb", 7, 40.0);
  const SimConfig agile_config = make_scenario("agile", 7, 40.0);
  Flight climbing(climb_config.flight, climb_config.duration_s, climb_config.seed);
  Flight level(agile_config.flight, agile_config.duration_s, agile_config.seed);

  const Samples climb = simulate(climb_config), agile = simulate(agile_config);
  const auto thrust = [](const SimSample& s) { return -s.truth.specific_force.z(); };
  for (std::size_t i = 0; i < climb.size(); ++i) {
    const double t = climb[i].time_s;
    const FlightReference climbing_reference = climbing.plan().at(t), level_reference = level.plan().at(t);
    ASSERT_EQ(climbing_reference.roll.value, level_reference.roll.value);
    ASSERT_EQ(climbing_reference.pitch.value, level_reference.pitch.value);
    const double height = -climb[i].truth.position_ned.z() - climb_config.flight.start_altitude_m;
    ASSERT_NEAR(height, climbing_reference.height.value, 0.05) << "t=" << t;
    // The acceleration limit keeps the thrust well between free fall and the rotors' limit.
    ASSERT_GT(thrust(climb[i]), 0.4 * kGravity) << "t=" << t;
    ASSERT_LT(thrust(climb[i]), 2.0 * kGravity) << "t=" << t;
  }
  ASSERT_GT(climbing.plan().drawn().height.end_time(), 20.0);
  EXPECT_EQ(level.plan().drawn().height.end_time(), 0.0);
  EXPECT_NEAR(-climb.back().truth.position_ned.z(), climb_config.flight.start_altitude_m, 0.01);
  const double climb_spread = stddev_of(climb, thrust), agile_spread = stddev_of(agile, thrust);
  EXPECT_GT(climb_spread, 0.1 * kGravity) << "tens of per cent";
  EXPECT_GT(climb_spread, 2.0 * agile_spread);
}

TEST(SimFlight, OmegaDotIsTheDerivativeOfOmega) {
  const Samples v = run("paper", 3, 20.0, {}, 1000.0);
  double worst = 0, peak = 0;
  for (std::size_t i = 1; i + 1 < v.size(); ++i) {
    const Vector3d numeric = (v[i + 1].truth.omega - v[i - 1].truth.omega) / (v[i + 1].time_s - v[i - 1].time_s);
    worst = std::max(worst, (numeric - v[i].truth.omega_dot).norm());
    peak = std::max(peak, v[i].truth.omega_dot.norm());
  }
  EXPECT_GT(peak, 20.0);
  EXPECT_LT(worst, 0.02 * peak);
}

// --- Accelerometer physics (docs/model.md) ------------------------------------------------------------------------

// The paper's eq. (7): without drag, an accelerometer at the mass centre reads no horizontal specific force, however
// the vehicle manoeuvres; and what it reads is what the velocity's derivative says. At 1200 Hz two samples in three
// fall between the 2 kHz physics steps, so this also checks the states interpolated by partial steps.
TEST(SimAccelerometer, DragFreeMassCentreReadsNoHorizontalForce) {
  const Samples v = run("center", 3, 20.0, {"quadratic_drag=0"}, 1200.0);
  for (std::size_t i = 1; i + 1 < v.size(); ++i) {
    const Vector3d f = differentiated_specific_force(v, i);
    ASSERT_LT(f.head<2>().norm(), 1e-3) << "t=" << v[i].time_s;
    ASSERT_LT((f - v[i].ideal.accel).norm(), 1e-2) << "t=" << v[i].time_s;
  }
}

TEST(SimAccelerometer, QuadraticDragReadsMinusMuAbsVV) {
  const Samples v = run("center", 3, 20.0, {}, 1000.0);
  double peak_drag = 0;
  for (std::size_t i = 1; i + 1 < v.size(); ++i) {
    const Vector3d& vb = v[i].truth.velocity_body;
    const Eigen::Vector2d drag(-kPaperMu * std::abs(vb.x()) * vb.x(), -kPaperMu * std::abs(vb.y()) * vb.y());
    peak_drag = std::max(peak_drag, drag.norm());
    ASSERT_LT((differentiated_specific_force(v, i).head<2>() - drag).norm(), 1e-3) << "t=" << v[i].time_s;
    ASSERT_LT((v[i].ideal.accel.head<2>() - drag).norm(), 1e-9) << "t=" << v[i].time_s;
  }
  EXPECT_GT(peak_drag, 0.05) << "the flight must be fast enough for the check to mean something";
}

TEST(SimAccelerometer, LinearDragReadsMinusKV) {
  const Samples v = run("center", 3, 20.0, {"quadratic_drag=0", "linear_drag=0.3"}, 1000.0);
  for (std::size_t i = 1; i + 1 < v.size(); ++i) {
    const Eigen::Vector2d drag = -0.3 * v[i].truth.velocity_body.head<2>();
    ASSERT_LT((differentiated_specific_force(v, i).head<2>() - drag).norm(), 1e-3) << "t=" << v[i].time_s;
  }
}

// Away from the mass centre the IMU reads its own point's acceleration: differentiate that point's position twice.
TEST(SimAccelerometer, LeverArmReadingIsThePointsAcceleration) {
  SimConfig config = make_scenario("paper", 5, 20.0);
  config.imu.rate_hz = 1000.0;
  config.imu.pose.sensor_from_body = Eigen::AngleAxisd(0.3, Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  config.imu.pose.position_m = {0.12, -0.08, -0.15};  // a full 3-D pose, not just the paper's plane
  const Samples v = simulate(config);
  const auto imu_position = [&](const SimSample& s) {
    return Vector3d(s.truth.position_ned + s.truth.attitude * config.imu.pose.position_m);
  };
  const double h = 1.0 / config.imu.rate_hz;
  double worst = 0, peak_lever = 0;
  for (std::size_t i = 1; i + 1 < v.size(); ++i) {
    const Vector3d a = (imu_position(v[i + 1]) - 2 * imu_position(v[i]) + imu_position(v[i - 1])) / (h * h);
    const Vector3d expected =
        config.imu.pose.sensor_from_body * (v[i].truth.attitude.conjugate() * (a - kGravity * kDown));
    worst = std::max(worst, (expected - v[i].ideal.accel).norm());
    peak_lever =
        std::max(peak_lever, (v[i].ideal.accel - config.imu.pose.sensor_from_body * v[i].truth.specific_force).norm());
  }
  EXPECT_GT(peak_lever, 3.0);
  EXPECT_LT(worst, 0.1);  // central differences across the controller's steps; 1 % of the lever-arm signal
}

// The paper's eq. (9) for pitch-only motion, from (r, beta, alpha) as the paper defines them.
TEST(SimAccelerometer, PaperPlacementGivesEquationNine) {
  SimConfig config = make_scenario("paper", 5, 20.0, std::vector<std::string>{"quadratic_drag=0"});
  config.flight.manoeuvres.roll_share = 0.0;  // pitch only, as the paper's eq. (9) assumes
  const Samples v = simulate(config);
  double peak = 0;
  for (const SimSample& s : v) {
    const double q = s.truth.omega.y(), q_dot = s.truth.omega_dot.y(), thrust = -s.truth.specific_force.z();
    const double r = kPaperR, b = kPaperBeta, a = kPaperAlpha;
    // Eq. (8) plus the lever arm's z component seen through sin(alpha), which eq. (9) drops (docs/model.md).
    const double lever_z = r * (q * q * std::sin(b) - q_dot * std::cos(b));
    const double eq8 = thrust * std::sin(a) - r * (q * q * std::cos(b) + q_dot * std::sin(b)) * std::cos(a);
    ASSERT_NEAR(s.ideal.accel.x(), eq8 - lever_z * std::sin(a), 1e-3) << "t=" << s.time_s;
    peak = std::max(peak, std::abs(eq8));
  }
  EXPECT_GT(peak, 3.0);
}

// What the estimator relies on: the paper's eq. (14) fitted to a simulated "paper" flight gives back the
// simulated (r, beta, alpha, mu). Linear least squares in (g sin a, -r cos b cos a, -r sin b cos a, mu), with the
// drag on the true body velocity (the paper's own v_X estimate is the estimator's business).
TEST(SimAccelerometer, PaperModelFitRecoversTheScenarioParameters) {
  const Samples v = run("paper", 6, 60.0);
  Eigen::MatrixXd a(v.size(), 4);
  Eigen::VectorXd f(v.size());
  for (std::size_t i = 0; i < v.size(); ++i) {
    const TrueState& t = v[i].truth;
    const double vx = t.velocity_body.x();
    a.row(i) << 1.0, t.omega.y() * t.omega.y(), t.omega_dot.y(), -std::abs(vx) * vx;
    f[i] = v[i].measured.accel.x();
  }
  const Eigen::Vector4d c = a.colPivHouseholderQr().solve(f);
  const double alpha = std::asin(c[0] / kGravity);
  EXPECT_NEAR(std::hypot(c[1], c[2]) / std::cos(alpha), kPaperR, 0.002);
  // Eq. (14) drops the lever arm's z component seen through sin(alpha) (docs/model.md); it adds 6 % to the small
  // r cos(beta) term, which moves beta by about +0.3 deg.
  EXPECT_NEAR(std::atan2(-c[2], -c[1]), kPaperBeta, 0.6 * std::numbers::pi / 180);
  EXPECT_NEAR(alpha, kPaperAlpha, 0.02 * std::numbers::pi / 180);
  EXPECT_NEAR(c[3], kPaperMu, 0.002);
}

TEST(SimAccelerometer, TiltAlphaShowsAsGSinAlpha) {
  const double alpha = 3.0 * std::numbers::pi / 180;
  SimConfig config = make_scenario("hover", 1, 5.0);
  config.imu.pose = ImuPose::paper(0.0, std::numbers::pi / 2, alpha);
  const Samples v = simulate(config);
  EXPECT_NEAR(v.back().ideal.accel.x(), kGravity * std::sin(alpha), 1e-9);
  EXPECT_NEAR(v.back().ideal.accel.z(), -kGravity * std::cos(alpha), 1e-9);
  EXPECT_NEAR(mean_of(v, [](const SimSample& s) { return s.measured.accel.x(); }), kGravity * std::sin(alpha), 0.005);
}

TEST(SimImu, MagnetometerSeesTheEarthFieldAndTemperatureDrifts) {
  const Samples v = run("paper", 2, 10.0);
  const ImuConfig imu;
  for (const SimSample& s : v) ASSERT_NEAR(s.ideal.mag.norm(), imu.earth_field_ned_ut.norm(), 1e-9);
  // Level at the start: the field as it is in NED (the paper pose's -0.3 deg tilt moves it by under 0.3 uT).
  EXPECT_LT((v.front().ideal.mag - imu.earth_field_ned_ut).norm(), 0.3);
  EXPECT_NEAR(v.back().measured.temperature_c - v.front().measured.temperature_c,
              imu.temperature_drift_c_per_s * v.back().time_s, 0.01);
}

// --- Effects ------------------------------------------------------------------------------------------------------

TEST(SimEffects, BiasesShiftTheMeanByTheBias) {
  const Samples v = run("hover", 1, 10.0, {"accel_bias=0.3,-0.2,0.5", "gyro_bias=0.02"});
  const Vector3d accel_bias(0.3, -0.2, 0.5);
  for (int axis = 0; axis < 3; ++axis) {
    EXPECT_NEAR(mean_of(v, [&](const SimSample& s) { return s.measured.accel[axis] - s.ideal.accel[axis]; }),
                accel_bias[axis], 0.005);
    EXPECT_NEAR(mean_of(v, [&](const SimSample& s) { return s.measured.gyro[axis] - s.ideal.gyro[axis]; }), 0.02,
                0.001);
  }
}

TEST(SimEffects, ScaleAndCrossAxisCouplingMixTheAxes) {
  const Samples scaled = run("hover", 1, 5.0, {"accel_scale=0.02"});
  EXPECT_NEAR(mean_of(scaled, [](const SimSample& s) { return s.measured.accel.z(); }), -1.02 * kGravity, 0.005);
  // 1 % of every other axis: hovering, x reads 1 % of z's -g.
  const Samples crossed = run("hover", 1, 5.0, {"accel_cross=0.01"});
  EXPECT_NEAR(mean_of(crossed, [](const SimSample& s) { return s.measured.accel.x(); }), -0.01 * kGravity, 0.005);
  EXPECT_NEAR(mean_of(crossed, [](const SimSample& s) { return s.measured.accel.z(); }), -kGravity, 0.005);
}

TEST(SimEffects, NoiseDensitySetsThePerSampleSpread) {
  const Samples v = run("hover", 1, 10.0, {"accel_noise=0.02", "gyro_noise=0.002"}, 500.0);
  const double bandwidth = 500.0 / 2;
  for (int axis = 0; axis < 3; ++axis) {
    EXPECT_NEAR(stddev_of(v, [&](const SimSample& s) { return s.measured.accel[axis]; }), 0.02 * std::sqrt(bandwidth),
                0.02);
    EXPECT_NEAR(stddev_of(v, [&](const SimSample& s) { return s.measured.gyro[axis]; }), 0.002 * std::sqrt(bandwidth),
                0.002);
  }
}

// The accelerometer's series is the gyro-time series shifted by tau: the cross-correlation peaks at tau.
TEST(SimEffects, TimeOffsetShiftsTheCrossCorrelationPeak) {
  for (const double tau : {0.02, -0.015}) {
    const Samples v = run("paper", 4, 20.0, {"time_offset=" + std::to_string(tau)});
    int best_lag = 0;
    double best = -INFINITY;
    for (int lag = -10; lag <= 10; ++lag) {
      double c = 0;
      for (std::size_t i = 10; i + 10 < v.size(); ++i) c += v[i].measured.accel.x() * v[i - lag].ideal.accel.x();
      if (c > best) {
        best = c;
        best_lag = lag;
      }
    }
    EXPECT_EQ(best_lag, std::lround(tau * 200.0)) << "tau=" << tau;
  }
}

TEST(SimEffects, VibrationIsASpectralLineAtItsFrequency) {
  const Samples v = run("hover", 1, 10.0, {"vibration=37,0.5"});
  for (int axis : {0, 2}) {
    const auto residual = [&](const SimSample& s) { return s.measured.accel[axis] - s.ideal.accel[axis]; };
    EXPECT_NEAR(amplitude_at(v, 37.0, residual), 0.5, 0.02) << "axis " << axis;
    EXPECT_LT(amplitude_at(v, 23.0, residual), 0.02) << "axis " << axis;
  }
}

// A steady wind blows the hovering vehicle downwind until the position hold's tilt balances the drag on the air
// velocity (-wind): the accelerometer then reads +mu * w^2 into the wind's direction.
TEST(SimEffects, WindMovesTheDragToTheAirVelocity) {
  const double wind = 3.0;
  const Samples calm = run("hover", 1, 30.0);
  const Samples windy = run("hover", 1, 30.0, {"wind=3,0"});
  const auto settled = [](const Samples& v) { return Samples(v.end() - 1000, v.end()); };  // last 5 s
  const auto fx = [](const SimSample& s) { return s.measured.accel.x(); };
  EXPECT_NEAR(mean_of(settled(calm), fx), 0.0, 0.005);
  EXPECT_NEAR(mean_of(settled(windy), fx), kPaperMu * wind * wind, 0.05 * kPaperMu * wind * wind);
  EXPECT_GT(windy.back().truth.position_ned.x(), 0.1) << "blown north";
  EXPECT_GT(windy.back().truth.euler.y(), 0.02) << "nose up, leaning into the wind";
}

// --- Effect and scenario parsing ----------------------------------------------------------------------------------

TEST(SimEffectParsing, BadSpecsGiveOneLineListingEveryEffect) {
  for (const std::string spec : {"nonsense=1", "wind=1", "wind=a,b", "linear_drag=-1", "time_offset=nan",
                                 "accel_bias=", "accel_bias=1,2", "vibration", "gyro_noise=1e400", "=3"}) {
    SimConfig config;
    try {
      apply_effect(config, spec);
      ADD_FAILURE() << spec << " was accepted";
    } catch (const std::invalid_argument& e) {
      const std::string message = e.what();
      EXPECT_EQ(message.find('\n'), std::string::npos) << message;
      EXPECT_NE(message.find(spec), std::string::npos) << message;
      for (const EffectInfo& effect : effect_catalogue()) EXPECT_NE(message.find(effect.name), std::string::npos);
    }
  }
}

TEST(SimEffectParsing, AxisListsAndScalarsLandWhereDocumented) {
  SimConfig config;
  apply_effect(config, "accel_bias=0.1");
  EXPECT_EQ(config.imu.errors.accel_bias, Vector3d(0.1, 0.1, 0.1));
  apply_effect(config, "gyro_bias=1,2,3");
  EXPECT_EQ(config.imu.errors.gyro_bias, Vector3d(1, 2, 3));
  apply_effect(config, "wind=2,-1");
  EXPECT_EQ(config.flight.air.wind_ned, Vector3d(2, -1, 0));
  apply_effect(config, "accel_cross=0.1,0.2,0.3,0.4,0.5,-0.1");
  Eigen::Matrix3d expected;
  expected << 1, 0.1, 0.2, 0.3, 1, 0.4, 0.5, -0.1, 1;
  EXPECT_EQ(config.imu.errors.accel_scale_cross, expected);
}

TEST(SimScenario, UnknownNameAndBadDurationAreRejected) {
  EXPECT_THROW(make_scenario("loop", 1), std::invalid_argument);
  EXPECT_THROW(make_scenario("paper", 1, 0.0), std::invalid_argument);
  EXPECT_THROW(make_scenario("paper", 1, NAN), std::invalid_argument);
  EXPECT_EQ(make_scenario("paper", 1, kMaxDurationS).duration_s, 86400.0);
  for (const double too_long : {std::nextafter(kMaxDurationS, INFINITY), 1e7, 1e300, double(INFINITY)}) {
    try {
      make_scenario("paper", 1, too_long);
      ADD_FAILURE() << too_long << " s accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("at most 86400 s (24 h)"), std::string::npos) << e.what();
    }
  }
  for (std::string_view name : scenario_names()) EXPECT_NO_THROW(make_scenario(name, 1));
}

TEST(SimScenario, PaperAndCenterDifferOnlyInThePlacement) {
  const SimConfig paper = make_scenario("paper", 1), center = make_scenario("center", 1);
  EXPECT_NEAR(paper.imu.pose.position_m.norm(), kPaperR, 1e-12);
  EXPECT_NEAR(paper.imu.pose.sensor_from_body(0, 2), -std::sin(kPaperAlpha), 1e-12);  // sensor x: (cos a, 0, -sin a)
  EXPECT_EQ(center.imu.pose.position_m, Vector3d::Zero());
  EXPECT_EQ(paper.flight.air.quadratic_drag_per_m, kPaperMu);
  EXPECT_EQ(paper.duration_s, 60.0);
  EXPECT_EQ(paper.imu.rate_hz, 200.0);
}

// --- Flight plan --------------------------------------------------------------------------------------------------

TEST(SimTrajectory, CosineCurveRateAndAccelerationAreDerivatives) {
  CosineCurve c;
  c.add_knot(1.0, 0.0);
  c.add_knot(1.3, 0.25);
  c.add_knot(1.6, -0.25);
  c.add_knot(2.0, 0.0);
  const double h = 1e-5;
  for (double t = 1.01; t < 2.0; t += 0.037) {
    EXPECT_NEAR(c.at(t).rate, (c.at(t + h).value - c.at(t - h).value) / (2 * h), 1e-5) << t;
    EXPECT_NEAR(c.at(t).acceleration, (c.at(t + h).rate - c.at(t - h).rate) / (2 * h), 1e-4) << t;
  }
  // A swing +A -> -A over h is half a period of a sinusoid of period 2h.
  EXPECT_NEAR(c.at(1.3 + 0.075).value, 0.25 * std::cos(std::numbers::pi / 4), 1e-12);
  EXPECT_EQ(c.at(0.0).value, 0.0);
  EXPECT_EQ(c.at(1.3).rate, 0.0);
  EXPECT_EQ(c.at(5.0).value, 0.0);
}

TEST(SimTrajectory, ManoeuvresStayInsideTheirBoundsAndTheFlight) {
  const ManoeuvreConfig config;
  Rng rng(9);
  const Trajectory plan = plan_manoeuvres(config, 60.0, rng);
  EXPECT_LE(std::max(plan.roll.end_time(), plan.pitch.end_time()), 59.0);
  EXPECT_GT(std::min(plan.roll.end_time(), plan.pitch.end_time()), 30.0) << "both axes manoeuvre";
  for (double t = 0; t < 60.0; t += 0.01) {
    ASSERT_LE(std::abs(plan.pitch.at(t).value), config.amplitude_max_rad);
    ASSERT_LE(std::abs(plan.roll.at(t).value), config.amplitude_max_rad);
    if (t < config.first_start_s) {
      ASSERT_EQ(plan.pitch.at(t).value, 0.0);
    }
  }
  ManoeuvreConfig off = config;
  off.enabled = false;
  EXPECT_EQ(plan_manoeuvres(off, 60.0, rng).pitch.end_time(), 0.0);
}

TEST(SimTrajectory, VerticalManoeuvresStayInsideTheirHeightAndAcceleration) {
  VerticalManoeuvreConfig config;
  EXPECT_FALSE(config.enabled) << "off by default: the existing scenarios fly as before";
  config.enabled = true;
  Rng rng(9);
  const CosineCurve height = plan_vertical_manoeuvres(config, 60.0, rng);
  EXPECT_LE(height.end_time(), 59.0);
  EXPECT_GT(height.end_time(), 30.0);
  double lowest = 0.0, highest = 0.0;
  for (double t = 0; t < 60.0; t += 0.01) {
    ASSERT_LE(std::abs(height.at(t).value), config.height_max_m);
    ASSERT_LE(std::abs(height.at(t).acceleration), config.max_acceleration_mps2 + 1e-9);
    lowest = std::min(lowest, height.at(t).value);
    highest = std::max(highest, height.at(t).value);
  }
  EXPECT_LT(lowest, -config.height_min_m) << "descents";
  EXPECT_GT(highest, config.height_min_m) << "climbs";
  config.enabled = false;
  EXPECT_EQ(plan_vertical_manoeuvres(config, 60.0, rng).end_time(), 0.0);
}

// --- Streaming ----------------------------------------------------------------------------------------------------

std::uint64_t fnv1a(const std::vector<std::uint8_t>& bytes) {
  std::uint64_t hash = 14695981039346656037ull;
  for (const std::uint8_t b : bytes) hash = (hash ^ b) * 1099511628211ull;
  return hash;
}

// The flight plan is drawn as the flight goes; the samples are bit for bit those of the plan drawn whole before the
// flight, which is what the simulator did until then (the hashes are of its samples, every field).
TEST(SimStreaming, AFlightIsBitIdenticalToOneWithItsPlanDrawnWhole) {
  EXPECT_EQ(fnv1a(bytes_of(run("climb", 7, 30.0))), 0xe52d56ad304ad161ull);
  EXPECT_EQ(fnv1a(bytes_of(run("paper", 3, 30.0))), 0x87eae43958f7af34ull);
}

TEST(SimStreaming, ThePlanDrawnAsTheFlightGoesReadsAsTheWholePlan) {
  ManoeuvreConfig attitude;
  attitude.roll_share = 0.5;
  VerticalManoeuvreConfig vertical;
  vertical.enabled = true;
  Rng whole_attitude(9), whole_vertical(10);
  const Trajectory whole = [&] {
    Trajectory plan = plan_manoeuvres(attitude, 120.0, whole_attitude);
    plan.height = plan_vertical_manoeuvres(vertical, 120.0, whole_vertical);
    return plan;
  }();
  FlightPlan streamed(attitude, vertical, 120.0, Rng(9), Rng(10));
  const auto same = [](const CosineCurve::Point& a, const CosineCurve::Point& b) {
    return std::bit_cast<std::uint64_t>(a.value) == std::bit_cast<std::uint64_t>(b.value) &&
           std::bit_cast<std::uint64_t>(a.rate) == std::bit_cast<std::uint64_t>(b.rate) &&
           std::bit_cast<std::uint64_t>(a.acceleration) == std::bit_cast<std::uint64_t>(b.acceleration);
  };
  for (int i = 0; i <= 121'000; ++i) {
    const double t = i * 1e-3;
    const FlightReference a = streamed.at(t), b = whole.at(t);
    ASSERT_TRUE(same(a.roll, b.roll) && same(a.pitch, b.pitch) && same(a.height, b.height)) << "t=" << t;
    streamed.forget_before(t);
  }
}

// A day's plan has tens of thousands of manoeuvres; the flight holds the few around the present.
TEST(SimStreaming, TheFlightPlanHoldsOnlyThePresentHoweverLongTheFlight) {
  const SimConfig config = make_scenario("climb", 1, kMaxDurationS);
  Rng rng(1);
  const std::size_t whole = plan_manoeuvres(config.flight.manoeuvres, kMaxDurationS, rng).pitch.knot_count();
  FlightPlan plan(config.flight.manoeuvres, config.flight.vertical, kMaxDurationS, Rng(1), Rng(2));
  std::size_t most = 0;
  for (double t = 0; t < kMaxDurationS; t += 0.25) {
    plan.at(t);
    plan.forget_before(t);
    const Trajectory& drawn = plan.drawn();
    most = std::max(most, drawn.roll.knot_count() + drawn.pitch.knot_count() + drawn.height.knot_count());
  }
  EXPECT_GT(whole, 50'000u);
  EXPECT_LT(most, 100u);
  EXPECT_GT(plan.drawn().pitch.end_time(), kMaxDurationS - 30) << "the plan went on to the end";
}

}  // namespace
}  // namespace imubridge::sim
