// IMU axes: parsing, gravity detection, the auto rule, mismatch warnings, the reference frame's alignment, and the
// whole mechanism: one flight written in several IMU orientations identifies and estimates the same.
#include "estimator/imu_axes.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "identification/identify.hpp"
#include "pipeline/estimation_stage.hpp"
#include "sim/imu_series.hpp"
#include "sim/scenario.hpp"

namespace imubridge::estimator {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;

constexpr double kDeg = kPi / 180.0;

Matrix3d arbitrary_rotation() { return Eigen::AngleAxisd(2.0, Vector3d(1, 2, 3).normalized()).toRotationMatrix(); }

std::string r_spelling(const Matrix3d& r) {
  std::string s = "R:";
  char buffer[40];
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      std::snprintf(buffer, sizeof buffer, "%s%.17g", i + j == 0 ? "" : ",", r(i, j));
      s += buffer;
    }
  }
  return s;
}

// ---- parsing ----

TEST(ImuAxesParse, NamedConventions) {
  EXPECT_EQ(parse_imu_axes("frd").imu_to_body, Matrix3d::Identity());
  EXPECT_EQ(parse_imu_axes("flu").imu_to_body, Matrix3d(Vector3d(1, -1, -1).asDiagonal()));
  Matrix3d x_up;
  x_up << 0, 0, 1, 0, 1, 0, -1, 0, 0;
  EXPECT_EQ(parse_imu_axes("x-up").imu_to_body, x_up);
  for (const char* name : {"frd", "flu", "x-up", "x-down", "y-up", "y-down"}) {
    const ImuAxes a = parse_imu_axes(name);
    EXPECT_FALSE(a.automatic);
    EXPECT_EQ(to_string(a), name);
    EXPECT_NEAR(a.imu_to_body.determinant(), 1.0, 1e-15) << name;
  }
  EXPECT_TRUE(parse_imu_axes("auto").automatic);
  EXPECT_EQ(to_string(parse_imu_axes("auto")), "auto");
  EXPECT_TRUE(is_identity(parse_imu_axes("frd")));
  EXPECT_FALSE(is_identity(parse_imu_axes("auto")));
}

TEST(ImuAxesParse, MatrixAndQuaternion) {
  const Matrix3d r = arbitrary_rotation();
  const ImuAxes m = parse_imu_axes(r_spelling(r));
  EXPECT_LT((m.imu_to_body - r).norm(), 1e-15);
  EXPECT_LT((parse_imu_axes(to_string(m)).imu_to_body - r).norm(), 1e-15);  // round trip
  const Eigen::Quaterniond q(r);
  const ImuAxes from_q = parse_imu_axes("q:" + std::to_string(q.w()) + "," + std::to_string(q.x()) + "," +
                                        std::to_string(q.y()) + "," + std::to_string(q.z()));
  EXPECT_LT((from_q.imu_to_body - r).norm(), 1e-5);
  EXPECT_EQ(parse_imu_axes("q:1,0,0,0").imu_to_body, Matrix3d::Identity());
}

TEST(ImuAxesParse, BadSpellingsAreRejectedWithTheValidOnes) {
  for (const char* bad : {"", "FRD", "z-up", "R:1,0,0,0,1,0,0,0", "R:1,0,0,0,1,0,0,0,2", "R:1,0,0,0,1,0,0,0,-1",
                          "R:1,0,0,0,1,0,0,0,x", "q:1,0,0", "q:2,0,0,0", "q:0.5,0.5,0.5"}) {
    try {
      parse_imu_axes(bad);
      ADD_FAILURE() << "accepted '" << bad << "'";
    } catch (const std::invalid_argument& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("frd, flu, x-up"), std::string::npos) << what;
      EXPECT_EQ(what.find('\n'), std::string::npos) << what;
    }
  }
  try {
    parse_imu_axes("R:1,0,0,0,1,0,0,0,-1");
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("reflection"), std::string::npos) << e.what();
  }
  try {
    parse_imu_axes("R:1,0,0,0,1,0,0,0,2");
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("orthonormal"), std::string::npos) << e.what();
  }
}

// ---- from up ----

TEST(ImuAxesFromUp, SnapsToTheNearestAxis) {
  EXPECT_EQ(from_up(-Vector3d::UnitZ()).axes.name, "frd");
  EXPECT_EQ(from_up(Vector3d::UnitZ()).axes.name, "flu");
  EXPECT_EQ(from_up(Vector3d::UnitX()).axes.name, "x-up");
  EXPECT_EQ(from_up(Vector3d::UnitY()).axes.name, "y-up");
  EXPECT_EQ(from_up(Vector3d::UnitY()).axes.imu_to_body, parse_imu_axes("y-up").imu_to_body);
  for (const Vector3d& up : {Vector3d(0, 0, -1), Vector3d(0, 0, 1), Vector3d(1, 0, 0), Vector3d(0, 1, 0),
                             Vector3d(0, -1, 0), Vector3d(-1, 0, 0)}) {
    const UpSnap s = from_up(up);
    // Whatever the convention, the body sees up as (0, 0, -1), and the rotation is proper.
    EXPECT_LT((s.axes.imu_to_body * up - Vector3d(0, 0, -1)).norm(), 1e-15);
    EXPECT_NEAR(s.axes.imu_to_body.determinant(), 1.0, 1e-15);
    EXPECT_EQ(s.tilt_rad, 0.0);
  }
  const UpSnap tilted = from_up(Vector3d(0.3, 0.0, 1.0).normalized());
  EXPECT_EQ(tilted.axes.name, "flu");
  EXPECT_NEAR(tilted.tilt_rad, std::atan(0.3), 1e-12);
  const AxesResolution r = resolve_axes(auto_axes(), AxesDetection{Vector3d(0.3, 0.0, 1.0).normalized()});
  ASSERT_TRUE(r.note.has_value());  // 16.7 deg: more than kTiltNoteDegrees
  EXPECT_FALSE(r.mismatch.has_value());
}

// ---- detection ----

struct Samples {
  std::vector<double> t;
  std::vector<Vector3d> accel, gyro;
};

// `rest` seconds at rest (with MEMS-like noise), then `fly` seconds of a tilting, turning flight, in IMU axes R^T.
Samples synthetic(double rest, double fly, const Matrix3d& imu_to_body) {
  Samples s;
  std::uint64_t state = 12345;
  const auto noise = [&state] {  // a small deterministic LCG: uniform in [-1, 1]
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(state >> 11) / static_cast<double>(1ull << 52) - 1.0;
  };
  for (int k = 0; static_cast<double>(k) / 200.0 < rest + fly; ++k) {
    const double t = k / 200.0;
    Vector3d f(0, 0, -kGravity), w(0, 0, 0);
    if (t >= rest) {
      const double u = t - rest;
      f = Vector3d(3.0 * std::sin(2.0 * u), 2.0 * std::cos(1.3 * u), -kGravity - 1.0 * std::sin(0.7 * u));
      w = Vector3d(0.5 * std::sin(3.0 * u), 0.4 * std::cos(2.0 * u), 0.2);
    }
    f += 0.03 * Vector3d(noise(), noise(), noise());
    w += 0.003 * Vector3d(noise(), noise(), noise());
    s.t.push_back(t);
    s.accel.push_back(imu_to_body.transpose() * f);
    s.gyro.push_back(imu_to_body.transpose() * w);
  }
  return s;
}

TEST(ImuAxesDetect, AtRestBeforeTakeOff) {
  for (const char* name : {"frd", "flu", "x-up", "y-down"}) {
    const Samples s = synthetic(2.0, 10.0, parse_imu_axes(name).imu_to_body);
    const auto d = detect_up(s.t, s.accel, s.gyro);
    ASSERT_TRUE(d);
    EXPECT_EQ(d->method, UpMethod::at_rest);
    EXPECT_EQ(d->t_start, 0.0);
    EXPECT_GT(d->t_end, 1.8);
    EXPECT_LE(d->t_end, 2.05);
    EXPECT_EQ(from_up(d->up).axes.name, name);
    const AxesResolution r = resolve_axes(auto_axes(), d);
    EXPECT_EQ(r.axes.name, name);
    EXPECT_NE(r.description.find("at rest, 0.0-"), std::string::npos) << r.description;
    EXPECT_NE(r.description.find("IMU axes " + std::string(name) + " (auto: gravity"), std::string::npos)
        << r.description;
  }
}

TEST(ImuAxesDetect, InFlightFromTheMeanThrust) {
  for (const char* name : {"frd", "flu", "x-up"}) {
    const Samples s = synthetic(0.0, 20.0, parse_imu_axes(name).imu_to_body);
    const auto d = detect_up(s.t, s.accel, s.gyro);
    ASSERT_TRUE(d);
    EXPECT_EQ(d->method, UpMethod::in_flight);
    EXPECT_EQ(d->samples, s.t.size());
    EXPECT_EQ(from_up(d->up).axes.name, name);
  }
  EXPECT_FALSE(detect_up({}, {}, {}));
}

TEST(ImuAxesDetect, LiveDetectorDecidesAtRestOrAfterFlightSeconds) {
  const Samples rest = synthetic(2.0, 10.0, parse_imu_axes("flu").imu_to_body);
  UpDetector a;
  std::size_t k = 0;
  while (!a.add(rest.t[k], rest.accel[k], rest.gyro[k])) ++k;
  EXPECT_NEAR(rest.t[k], kRestWindowSeconds, 0.01);
  EXPECT_EQ(from_up(a.result()->up).axes.name, "flu");
  const Samples fly = synthetic(0.0, 20.0, parse_imu_axes("x-up").imu_to_body);
  UpDetector b;
  k = 0;
  while (!b.add(fly.t[k], fly.accel[k], fly.gyro[k])) ++k;
  EXPECT_NEAR(fly.t[k], kFlightDecisionSeconds, 0.01);
  EXPECT_EQ(b.result()->method, UpMethod::in_flight);
  EXPECT_EQ(from_up(b.result()->up).axes.name, "x-up");
}

TEST(ImuAxesResolve, DeclarationTheDataContradictIsKeptWithAWarning) {
  const Samples s = synthetic(2.0, 5.0, parse_imu_axes("x-up").imu_to_body);
  const auto d = detect_up(s.t, s.accel, s.gyro);
  const AxesResolution wrong = resolve_axes(parse_imu_axes("flu"), d);
  EXPECT_EQ(wrong.axes.name, "flu");  // the user's word stands
  ASSERT_TRUE(wrong.mismatch);
  EXPECT_NE(wrong.mismatch->find("declared flu"), std::string::npos) << *wrong.mismatch;
  EXPECT_NE(wrong.mismatch->find("+x"), std::string::npos) << *wrong.mismatch;
  EXPECT_NE(wrong.mismatch->find("--imu-axes x-up"), std::string::npos) << *wrong.mismatch;
  EXPECT_FALSE(resolve_axes(parse_imu_axes("x-up"), d).mismatch);
  EXPECT_FALSE(resolve_axes(parse_imu_axes("frd"), std::nullopt).mismatch);
  const AxesResolution nothing = resolve_axes(auto_axes(), std::nullopt);
  EXPECT_EQ(nothing.axes.name, "frd");
  EXPECT_TRUE(nothing.note);
}

// ---- the simulated flight in several orientations ----

const ImuSeries& paper_flight() {
  static const ImuSeries series = sim::imu_series(sim::simulate(sim::make_scenario("paper", 3, 30.0)));
  return series;
}

// The flight as an IMU mounted with R_bs would have written it: the vectors turned by R_bs^T, the reference the
// body's.
ImuSeries written_in(const ImuSeries& body, const Matrix3d& imu_to_body) {
  ImuSeries s = body;
  for (Vector3d& v : s.accel) v = imu_to_body.transpose() * v;
  for (Vector3d& v : s.gyro) v = imu_to_body.transpose() * v;
  return s;
}

// What replay::read_session_series does to a series read in IMU axes.
ImuSeries to_body(ImuSeries s, const ImuAxes& declared, ReferenceFrame expected_frame) {
  const AxesResolution r = resolve_axes(declared, detect_up(s));
  EXPECT_FALSE(r.mismatch) << *r.mismatch;
  const ReferenceAlignment a = align_reference_frame(s, r.axes.imu_to_body);
  EXPECT_EQ(a.frame, expected_frame) << describe(a);
  rotate_to_body(s, r.axes.imu_to_body, a.ref_from_imu);
  return s;
}

TEST(ImuAxesReference, AlignmentRecoversAKnownRotation) {
  // A reference kept in a frame M away from the IMU's: q_ref = q_body * M^T.
  const Matrix3d m = Eigen::AngleAxisd(0.7, Vector3d(0.2, -1.0, 0.5).normalized()).toRotationMatrix();
  ImuSeries s = paper_flight();
  for (Eigen::Quaterniond& q : s.reference->attitude) q = q * Eigen::Quaterniond(Matrix3d(m.transpose()));
  const ReferenceAlignment a = align_reference_frame(s, Matrix3d::Identity());
  EXPECT_EQ(a.frame, ReferenceFrame::estimated) << describe(a);
  // The simulated IMU is tilted by the paper's alpha (-0.3 deg) from the body: the estimate carries it.
  EXPECT_LT(Eigen::AngleAxisd(Matrix3d(a.estimate.transpose() * m)).angle(), 0.5 * kDeg) << describe(a);
  EXPECT_LT(a.rms_misfit_rad, 0.01);
  EXPECT_GE(a.spans, kAlignMinSpans);
  // A reference without rotation cannot tell: it falls back to the IMU's frame and says so.
  ImuSeries still = paper_flight();
  for (auto& q : still.reference->attitude) q = Eigen::Quaterniond::Identity();
  const ReferenceAlignment none = align_reference_frame(still, parse_imu_axes("flu").imu_to_body);
  EXPECT_EQ(none.frame, ReferenceFrame::cannot_tell);
  EXPECT_TRUE(none.ref_from_imu.isIdentity());
  EXPECT_NE(describe(none).find("too little rotation"), std::string::npos) << describe(none);
}

// A flight that only yaws, its reference the body's: rotations about one axis, which leave Wahba's rotation about it
// undetermined.
ImuSeries yawing_flight() {
  ImuSeries s;
  s.reference.emplace();
  double yaw = 0.0;
  for (int k = 0; k < 4000; ++k) {
    const double t = k * 0.005;
    const double rate = 0.6 * std::sin(2.0 * kPi * 0.2 * t);
    if (k > 0) yaw += 0.5 * (rate + s.gyro.back().z()) * 0.005;
    s.t.push_back(t);
    s.gyro.emplace_back(0.0, 0.0, rate);
    s.accel.emplace_back(0.0, 0.0, -kGravity);
    s.reference->attitude.emplace_back(Eigen::AngleAxisd(yaw, Vector3d::UnitZ()));
    s.reference->velocity_ned.push_back(Vector3d::Zero());
  }
  return s;
}

TEST(ImuAxesReference, ALoggersGapIsLeftOutNotTakenForARotation) {
  // 10 s without samples (every topic of a log stops, as in the X500 flight): the reference turned, the gyro saw none.
  const ImuSeries& whole = paper_flight();
  ImuSeries gapped;
  gapped.reference.emplace();
  for (std::size_t k = 0; k < whole.size(); ++k) {
    if (whole.t[k] >= 10.0 && whole.t[k] < 20.0) continue;
    gapped.t.push_back(whole.t[k]);
    gapped.gyro.push_back(whole.gyro[k]);
    gapped.accel.push_back(whole.accel[k]);
    gapped.reference->attitude.push_back(whole.reference->attitude[k]);
    gapped.reference->velocity_ned.push_back(whole.reference->velocity_ned[k]);
  }
  const ReferenceAlignment a = align_reference_frame(gapped, Matrix3d::Identity());
  EXPECT_EQ(a.frame, ReferenceFrame::imu) << describe(a);
  EXPECT_LT(a.misfit_as_imu_rad, 0.01) << describe(a);
}

TEST(ImuAxesReference, AYawOnlyFlightStillTellsAnUpsideDownImuFromTheBody) {
  // Strapped on z up: the gyro reads the yaw with the opposite sign, which only the body's frame explains.
  const Matrix3d flu = parse_imu_axes("flu").imu_to_body;
  const ReferenceAlignment a = align_reference_frame(written_in(yawing_flight(), flu), flu);
  EXPECT_FALSE(a.estimate_determined) << describe(a);
  EXPECT_EQ(a.frame, ReferenceFrame::body) << describe(a);
  EXPECT_TRUE(a.ref_from_imu.isApprox(flu));
  EXPECT_GT(a.misfit_as_imu_rad, kAlignMinContrast * a.misfit_as_body_rad) << describe(a);
}

TEST(ImuAxesReference, AYawOnlyFlightCannotTellFramesThatDifferOnlyInYawAndSaysSo) {
  // Strapped on turned 90 deg about z: about the one axis the flight turns about, both frames read the same.
  const Matrix3d yawed = Eigen::AngleAxisd(0.5 * kPi, Vector3d::UnitZ()).toRotationMatrix();
  const ReferenceAlignment a = align_reference_frame(written_in(yawing_flight(), yawed), yawed);
  EXPECT_GE(a.spans, kAlignMinSpans);
  EXPECT_EQ(a.frame, ReferenceFrame::cannot_tell) << describe(a);
  EXPECT_NE(describe(a).find("cannot tell"), std::string::npos) << describe(a);
}

TEST(ImuAxesReference, AnFrdFlightWithTheBodysReferenceComesOutBitForBit) {
  const ImuSeries& body = paper_flight();
  const ImuSeries out = to_body(body, auto_axes(), ReferenceFrame::imu);
  EXPECT_EQ(out.accel, body.accel);
  EXPECT_EQ(out.gyro, body.gyro);
  for (std::size_t k = 0; k < body.size(); ++k) {
    ASSERT_EQ(out.reference->attitude[k].coeffs(), body.reference->attitude[k].coeffs());
  }
}

TEST(ImuAxesOrientation, OneFlightInFrdFluAndAnyRotationIdentifiesAndEstimatesTheSame) {
  const ImuSeries& body = paper_flight();
  IdentifyOptions o;
  o.model = ModelKind::full;
  o.velocity = VelocitySource::reference;
  o.train = TimeWindow{0.0, 20.0};
  const IdentifyResult base = identify(to_body(body, parse_imu_axes("frd"), ReferenceFrame::imu), o);
  const VelocityEvaluation base_v = evaluate_velocity(body, base.params.full);

  const Matrix3d arbitrary = arbitrary_rotation();
  struct Case {
    const char* what;
    Matrix3d imu_to_body;
    ImuAxes declared;
    ReferenceFrame frame;
  };
  const std::vector<Case> cases{
      {"flu declared", parse_imu_axes("flu").imu_to_body, parse_imu_axes("flu"), ReferenceFrame::body},
      {"flu auto", parse_imu_axes("flu").imu_to_body, auto_axes(), ReferenceFrame::body},
      {"x-up auto", parse_imu_axes("x-up").imu_to_body, auto_axes(), ReferenceFrame::body},
      {"R: declared", arbitrary, parse_imu_axes(r_spelling(arbitrary)), ReferenceFrame::body},
      {"q: declared", arbitrary, parse_imu_axes([&] {
         const Eigen::Quaterniond q(arbitrary);
         char buffer[128];
         std::snprintf(buffer, sizeof buffer, "q:%.17g,%.17g,%.17g,%.17g", q.w(), q.x(), q.y(), q.z());
         return std::string(buffer);
       }()),
       ReferenceFrame::body},
  };
  const auto near = [](const auto& a, const auto& b, const char* what, const std::string& name) {
    const double scale = std::max(1e-3, b.norm());
    EXPECT_LT((a - b).norm(), 1e-9 * scale) << name << " " << what << ": " << a.transpose() << " vs " << b.transpose();
  };
  for (const Case& c : cases) {
    const ImuSeries series = to_body(written_in(body, c.imu_to_body), c.declared, c.frame);
    const IdentifyResult r = identify(series, o);
    const FullModelParams& p = r.params.full;
    const FullModelParams& q = base.params.full;
    near(p.lever_arm, q.lever_arm, "lever arm", c.what);
    near(p.mounting, q.mounting, "mounting", c.what);
    near(p.drag_linear, q.drag_linear, "linear drag", c.what);
    near(p.drag_quadratic, q.drag_quadratic, "quadratic drag", c.what);
    near(p.accel_bias, q.accel_bias, "bias", c.what);
    const VelocityEvaluation v = evaluate_velocity(series, p);
    near(v.estimator.axis, base_v.estimator.axis, "velocity RMSE", c.what);
    EXPECT_EQ(v.samples, base_v.samples) << c.what;
  }
}

// ---- live ----

TEST(ImuAxesStage, AutoLinkWaitsThenGivesTheFrdEstimatesBitForBit) {
  const ImuSeries& body = paper_flight();
  ModelParams params;
  params.full.lever_arm = {0.1, 0.0, -0.05};
  params.full.drag_quadratic = {0.3, 0.3};
  const auto samples = [&](const Matrix3d& imu_to_body) {
    std::vector<protocol::Sample> out;
    for (std::size_t k = 0; k < body.size(); ++k) {
      protocol::Sample s;
      s.source.link = 3;
      s.seq = k;
      s.device_time_us = static_cast<std::int64_t>(k) * 5000;
      const Vector3d a = imu_to_body.transpose() * body.accel[k], w = imu_to_body.transpose() * body.gyro[k];
      s.accel = {a.x(), a.y(), a.z()};
      s.gyro = {w.x(), w.y(), w.z()};
      out.push_back(s);
    }
    return out;
  };
  pipeline::EstimationStage frd(params);
  std::vector<store::Estimate> expected;
  for (const auto& s : samples(Matrix3d::Identity())) {
    if (auto e = frd.update(s)) expected.push_back(*e);
  }
  std::vector<std::string> resolved;
  pipeline::StageAxes axes;
  axes.on_resolved = [&](const protocol::SourceKey&, const AxesResolution& r) { resolved.push_back(r.description); };
  pipeline::EstimationStage flu(params, axes);
  std::vector<store::Estimate> got;
  for (const auto& s : samples(parse_imu_axes("flu").imu_to_body)) flu.update(s, got);
  flu.finish(got);
  ASSERT_EQ(resolved.size(), 1u);
  EXPECT_NE(resolved[0].find("IMU axes flu (auto"), std::string::npos) << resolved[0];
  ASSERT_EQ(got.size(), expected.size());
  for (std::size_t k = 0; k < got.size(); ++k) ASSERT_EQ(got[k], expected[k]) << k;  // flu only flips signs
}

}  // namespace
}  // namespace imubridge::estimator
