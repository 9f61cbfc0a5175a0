#include "estimator/imu_axes.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <vector>

#include "estimator/constants.hpp"

namespace imubridge::estimator {
namespace {

using Eigen::Matrix3d;
using Eigen::Quaterniond;
using Eigen::Vector3d;

constexpr const char* kSpellings =
    "frd, flu, x-up, x-down, y-up, y-down, auto, R:r00,r01,r02,r10,r11,r12,r20,r21,r22 (row-major IMU->body "
    "rotation) or q:w,x,y,z (IMU->body quaternion)";

[[noreturn]] void bad(std::string_view text, const std::string& why) {
  throw std::invalid_argument("IMU axes '" + std::string(text) + "': " + why + "; valid: " + kSpellings);
}

// Rows are the body axes (forward, right, down) in IMU coordinates.
Matrix3d rows(const Vector3d& x, const Vector3d& y, const Vector3d& z) {
  Matrix3d r;
  r.row(0) = x.transpose();
  r.row(1) = y.transpose();
  r.row(2) = z.transpose();
  return r;
}

// The auto rule for the signed IMU axis `up_axis` (unit, one non-zero component).
Matrix3d rule(const Vector3d& up_axis) {
  const Vector3d z = -up_axis;
  const Vector3d x = std::abs(up_axis.x()) > 0.5 ? Vector3d::UnitZ() : Vector3d::UnitX();
  return rows(x, z.cross(x), z);
}

struct Named {
  const char* name;
  Vector3d up;  // the IMU axis pointing up
};
const std::array<Named, 6> kNamed{{{"frd", -Vector3d::UnitZ()},
                                   {"flu", Vector3d::UnitZ()},
                                   {"x-up", Vector3d::UnitX()},
                                   {"x-down", -Vector3d::UnitX()},
                                   {"y-up", Vector3d::UnitY()},
                                   {"y-down", -Vector3d::UnitY()}}};

ImuAxes named(const Named& n) { return {rule(n.up), n.name, false}; }

std::vector<double> numbers(std::string_view text, std::string_view list, std::size_t count) {
  std::vector<double> v;
  std::string s(list);
  std::size_t pos = 0;
  while (pos <= s.size()) {
    const std::size_t comma = std::min(s.find(',', pos), s.size());
    const std::string item = s.substr(pos, comma - pos);
    std::size_t used = 0;
    double x = 0.0;
    try {
      x = std::stod(item, &used);
    } catch (const std::exception&) {
      bad(text, "'" + item + "' is not a number");
    }
    if (used != item.size() || !std::isfinite(x)) bad(text, "'" + item + "' is not a number");
    v.push_back(x);
    pos = comma + 1;
  }
  if (v.size() != count) bad(text, "expected " + std::to_string(count) + " numbers, got " + std::to_string(v.size()));
  return v;
}

std::string axis_name(const Vector3d& axis) {
  int i = 0;
  axis.cwiseAbs().maxCoeff(&i);
  return std::string(axis[i] < 0 ? "-" : "+") + "xyz"[i];
}

double angle_between(const Vector3d& a, const Vector3d& b) { return std::atan2(a.cross(b).norm(), a.dot(b)); }

double rotation_angle(const Matrix3d& a, const Matrix3d& b) {
  return Eigen::AngleAxisd(Matrix3d(a.transpose() * b)).angle();
}

std::string format(const char* fmt, double a, double b = 0.0) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, fmt, a, b);
  return buffer;
}

Vector3d log_rotation(const Quaterniond& q) {
  const Eigen::AngleAxisd aa(q);
  return aa.angle() * aa.axis();
}

// Running sums for the rest tests over [i, j).
struct Prefix {
  std::vector<double> gyro2{0.0}, norm{0.0}, norm2{0.0};
  std::vector<Vector3d> accel{Vector3d::Zero()};
  void add(const Vector3d& a, const Vector3d& w) {
    gyro2.push_back(gyro2.back() + w.squaredNorm());
    norm.push_back(norm.back() + a.norm());
    norm2.push_back(norm2.back() + a.squaredNorm());
    accel.push_back(accel.back() + a);
  }
  bool at_rest(std::size_t i, std::size_t j) const {
    const double n = static_cast<double>(j - i);
    const double gyro_rms = std::sqrt(std::max(0.0, (gyro2[j] - gyro2[i]) / n));
    const double mean_norm = (norm[j] - norm[i]) / n;
    const Vector3d mean = (accel[j] - accel[i]) / n;
    const double spread = std::sqrt(std::max(0.0, (norm2[j] - norm2[i]) / n - mean.squaredNorm()));
    return gyro_rms < kRestMaxGyroRms && std::abs(mean_norm - kGravity) < kRestNormTolerance * kGravity &&
           spread < kRestMaxAccelSpread;
  }
  Vector3d mean(std::size_t i, std::size_t j) const { return (accel[j] - accel[i]) / static_cast<double>(j - i); }
};

// The first at-rest segment among the first `n` samples, extended while every trailing window stays at rest.
std::optional<AxesDetection> find_rest(std::span<const double> t, const Prefix& p, std::size_t n, bool extend) {
  std::size_t j = 0;
  for (std::size_t i = 0; i < n && t[i] - t[0] <= kRestSearchSeconds; ++i) {
    if (j <= i) j = i + 1;
    while (j < n && t[j - 1] - t[i] < kRestWindowSeconds) ++j;
    if (t[j - 1] - t[i] < kRestWindowSeconds) return std::nullopt;  // not enough samples left
    if (!p.at_rest(i, j)) continue;
    if (extend) {
      std::size_t k = i;  // start of the trailing window ending at j
      while (j < n) {
        while (t[j] - t[k + 1] >= kRestWindowSeconds) ++k;
        if (!p.at_rest(k, j + 1)) break;
        ++j;
      }
    }
    AxesDetection d;
    d.up = p.mean(i, j).normalized();
    d.method = UpMethod::at_rest;
    d.t_start = t[i];
    d.t_end = t[j - 1];
    d.samples = j - i;
    return d;
  }
  return std::nullopt;
}

std::optional<AxesDetection> in_flight(std::span<const double> t, const Prefix& p, std::size_t n) {
  if (n == 0) return std::nullopt;
  const Vector3d mean = p.mean(0, n);
  if (mean.norm() < kMinMeanSpecificForce) return std::nullopt;
  return AxesDetection{mean.normalized(), UpMethod::in_flight, t[0], t[n - 1], n};
}

}  // namespace

ImuAxes frd_axes() { return named(kNamed[0]); }
ImuAxes auto_axes() { return {}; }

ImuAxes parse_imu_axes(std::string_view text) {
  if (text == "auto") return auto_axes();
  for (const Named& n : kNamed) {
    if (text == n.name) return named(n);
  }
  if (text.starts_with("R:")) {
    const std::vector<double> v = numbers(text, text.substr(2), 9);
    const Matrix3d r = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(v.data());
    const double off = (r * r.transpose() - Matrix3d::Identity()).cwiseAbs().maxCoeff();
    if (off > 1e-6) bad(text, format("not orthonormal (R R^T differs from I by %.3g)", off));
    if (r.determinant() < 0.0) bad(text, "a reflection (det -1), not a rotation");
    return {r, std::string(text), false};
  }
  if (text.starts_with("q:")) {
    const std::vector<double> v = numbers(text, text.substr(2), 4);
    Quaterniond q(v[0], v[1], v[2], v[3]);
    if (std::abs(q.norm() - 1.0) > 1e-3) bad(text, format("quaternion of norm %.6g, not unit", q.norm()));
    return {q.normalized().toRotationMatrix(), std::string(text), false};
  }
  bad(text, "unknown");
}

std::string to_string(const ImuAxes& axes) {
  if (axes.automatic) return "auto";
  for (const Named& n : kNamed) {
    if (axes.name == n.name) return axes.name;
  }
  std::string s = "R:";
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      char buffer[32];
      std::snprintf(buffer, sizeof buffer, "%.17g", axes.imu_to_body(i, j));
      s += (i + j == 0 ? "" : ",") + std::string(buffer);
    }
  }
  return s;
}

bool is_identity(const ImuAxes& axes) { return !axes.automatic && axes.imu_to_body == Matrix3d::Identity(); }

std::string_view name(UpMethod method) { return method == UpMethod::at_rest ? "at rest" : "in flight"; }

std::string describe(const AxesDetection& d) {
  const UpSnap snap = from_up(d.up);
  std::string s = "gravity " + axis_name(snap.axis) + " " + std::string(name(d.method)) +
                  format(", %.1f-%.1f s", d.t_start, d.t_end);
  if (snap.tilt_rad * 180.0 / kPi > kTiltNoteDegrees) s += format(", tilted %.0f deg from it", snap.tilt_rad * 180 / kPi);
  return s;
}

std::optional<AxesDetection> detect_up(std::span<const double> t, std::span<const Vector3d> accel,
                                       std::span<const Vector3d> gyro) {
  if (t.size() != accel.size() || t.size() != gyro.size())
    throw std::invalid_argument("detect_up: t, accel and gyro differ in length");
  Prefix p;
  for (std::size_t k = 0; k < t.size(); ++k) p.add(accel[k], gyro[k]);
  if (auto rest = find_rest(t, p, t.size(), /*extend=*/true)) return rest;
  return in_flight(t, p, t.size());
}

std::optional<AxesDetection> detect_up(const ImuSeries& series) {
  return detect_up(series.t, series.accel, series.gyro);
}

bool UpDetector::add(double t, const Vector3d& accel, const Vector3d& gyro) {
  if (decided_) return true;
  t_.push_back(t);
  accel_.push_back(accel);
  gyro_.push_back(gyro);
  const double span = t_.back() - t_.front();
  // Only the window ending at the newest sample is new: the latest start at least kRestWindowSeconds back.
  if (span >= kRestWindowSeconds) {
    std::size_t i = t_.size() - 1;
    while (i > 0 && t_.back() - t_[i] < kRestWindowSeconds) --i;
    Prefix p;
    for (std::size_t k = i; k < t_.size(); ++k) p.add(accel_[k], gyro_[k]);
    const std::size_t n = t_.size() - i;
    if (p.at_rest(0, n)) {
      result_ = AxesDetection{p.mean(0, n).normalized(), UpMethod::at_rest, t_[i], t_.back(), n};
      decided_ = true;
    }
  }
  if (!decided_ && span >= kFlightDecisionSeconds) {
    Prefix p;
    for (std::size_t k = 0; k < t_.size(); ++k) p.add(accel_[k], gyro_[k]);
    result_ = in_flight(t_, p, t_.size());  // nothing when the mean says nothing: the caller assumes
    decided_ = true;
  }
  if (decided_) {
    t_ = {};
    accel_ = {};
    gyro_ = {};
  }
  return decided_;
}

UpSnap from_up(const Vector3d& up) {
  int i = 0;
  up.cwiseAbs().maxCoeff(&i);
  Vector3d axis = Vector3d::Zero();
  axis[i] = up[i] < 0.0 ? -1.0 : 1.0;
  UpSnap snap{{rule(axis), "", false}, axis, angle_between(up, axis)};
  for (const Named& n : kNamed) {
    if (n.up == axis) snap.axes.name = n.name;
  }
  return snap;
}

AxesResolution resolve_axes(const ImuAxes& declared, const std::optional<AxesDetection>& detection) {
  AxesResolution r;
  r.declared = declared;
  r.detection = detection;
  if (declared.automatic) {
    if (detection) {
      const UpSnap snap = from_up(detection->up);
      r.axes = snap.axes;
      r.description = "IMU axes " + to_string(r.axes) + " (auto: " + describe(*detection) + ")";
      if (snap.tilt_rad * 180.0 / kPi > kTiltNoteDegrees) {
        r.note = format("the detected up is %.0f deg from the IMU's ", snap.tilt_rad * 180.0 / kPi) +
                 axis_name(snap.axis) +
                 " axis: the fitted mounting rotation absorbs it; declare the exact rotation with --imu-axes R:... "
                 "or q:... if it is known";
      }
    } else {
      r.axes = frd_axes();
      r.description = "IMU axes frd (auto: gravity not detected, assumed)";
      r.note = "could not detect which way is up (no rest segment and no steady thrust): assuming frd; declare "
               "--imu-axes if that is wrong";
    }
    return r;
  }
  r.axes = declared;
  r.description = "IMU axes " + to_string(declared) + " (declared" +
                  (detection ? "; " + describe(*detection) : std::string()) + ")";
  if (detection) {
    const double angle = angle_between(declared.imu_to_body * detection->up, -Vector3d::UnitZ());
    if (angle * 180.0 / kPi > kMismatchDegrees) {
      const UpSnap snap = from_up(detection->up);
      r.mismatch = "IMU axes declared " + to_string(declared) + ", but the data's up is the IMU's " +
                   axis_name(snap.axis) + " axis (" + describe(*detection) + format("; %.0f deg off", angle * 180 / kPi) +
                   "): declare --imu-axes " + snap.axes.name + " (or auto)";
    }
  }
  return r;
}

std::string_view name(ReferenceFrame frame) {
  switch (frame) {
    case ReferenceFrame::imu: return "the IMU's";
    case ReferenceFrame::body: return "the body's";
    case ReferenceFrame::estimated: return "estimated";
    case ReferenceFrame::cannot_tell: return "cannot tell the IMU's from the body's";
  }
  return "?";
}

std::string describe(const ReferenceAlignment& a) {
  std::string s = "reference attitude frame: " + std::string(name(a.frame));
  if (a.spans < kAlignMinSpans)
    return s + " (too little rotation to tell: " + std::to_string(a.spans) + " spans turning, " +
           std::to_string(kAlignMinSpans) + " needed)";
  s += " (" + std::to_string(a.spans) + " spans" +
       format(", misfit as the IMU's %.2f deg", a.misfit_as_imu_rad * 180 / kPi) +
       format(", as the body's %.2f deg RMS", a.misfit_as_body_rad * 180 / kPi) +
       format(", singular values %.3g, %.3g", a.singular_values[0], a.singular_values[1]) +
       format(", %.3g", a.singular_values[2]);
  if (a.frame == ReferenceFrame::cannot_tell)
    s += format(": a contrast of %.1f needed", kAlignMinContrast);
  else if (a.estimate_determined)
    s += format(", estimate %.1f deg from it", a.snap_angle_rad * 180 / kPi);
  return s + ")";
}

std::vector<SpanRotation> span_rotations(std::span<const double> t, std::span<const Vector3d> gyro,
                                         std::span<const Quaterniond> attitude, std::size_t first, std::size_t end,
                                         double span_seconds) {
  std::vector<SpanRotation> out;
  end = std::min({end, t.size(), gyro.size(), attitude.size()});
  std::size_t a = first;
  while (a + 1 < end) {
    std::size_t b = a;
    Quaterniond turned = Quaterniond::Identity();
    bool gap = false;
    while (b + 1 < end && t[b] - t[a] < span_seconds) {
      const double dt = t[b + 1] - t[b];
      // A gap in the samples (a logger's dropout): the gyro did not see that rotation, so the span says nothing.
      gap = gap || dt > span_seconds;
      const Vector3d w = 0.5 * (gyro[b] + gyro[b + 1]) * dt;
      const double angle = w.norm();
      turned = turned * (angle > 0.0 ? Quaterniond(Eigen::AngleAxisd(angle, w / angle)) : Quaterniond::Identity());
      ++b;
    }
    if (t[b] - t[a] < span_seconds) break;
    if (!gap) out.push_back({log_rotation(attitude[a].conjugate() * attitude[b]), log_rotation(turned), t[b] - t[a]});
    a = b;
  }
  return out;
}

ReferenceAlignment align_reference_frame(const ImuSeries& series, const Matrix3d& imu_to_body) {
  if (!series.reference) throw std::invalid_argument("align_reference_frame: the series has no reference");
  ReferenceAlignment out;
  std::vector<std::pair<Vector3d, Vector3d>> pairs;  // (reference frame, IMU axes)
  for (const SpanRotation& s :
       span_rotations(series.t, series.gyro, series.reference->attitude, 0, series.size(), kAlignSpanSeconds)) {
    if (s.reference.norm() > kAlignMinSpanAngle && s.gyro.norm() > kAlignMinSpanAngle)
      pairs.emplace_back(s.reference, s.gyro);
  }
  out.spans = pairs.size();
  if (pairs.size() < kAlignMinSpans) return out;  // cannot_tell
  const auto misfit = [&pairs](const Matrix3d& r) {
    double sum = 0.0;
    for (const auto& [r_ref, r_imu] : pairs) sum += (r_ref - r * r_imu).squaredNorm();
    return std::sqrt(sum / static_cast<double>(pairs.size()));
  };
  out.misfit_as_imu_rad = misfit(Matrix3d::Identity());
  out.misfit_as_body_rad = misfit(imu_to_body);
  Matrix3d b = Matrix3d::Zero();
  for (const auto& [r_ref, r_imu] : pairs) b += r_ref * r_imu.transpose();
  // Dynamic size: GCC 12 warns (falsely) about the fixed-size JacobiSVD's uninitialised storage.
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(Eigen::MatrixXd(b), Eigen::ComputeFullU | Eigen::ComputeFullV);
  out.singular_values = svd.singularValues();
  const double snap = kAlignSnapDegrees * kPi / 180.0;
  out.estimate_determined = out.singular_values[1] >= kAlignMinSingularRatio * out.singular_values[0];
  if (out.estimate_determined) {
    Matrix3d d = Matrix3d::Identity();
    const Matrix3d u = svd.matrixU(), v = svd.matrixV();
    d(2, 2) = (u * v.transpose()).determinant() < 0.0 ? -1.0 : 1.0;
    out.estimate = u * d * v.transpose();
    out.rms_misfit_rad = misfit(out.estimate);
    // Neither of the two frames a reference is kept in: the estimate itself.
    if (std::min(rotation_angle(out.estimate, Matrix3d::Identity()), rotation_angle(out.estimate, imu_to_body)) >
        snap) {
      out.frame = ReferenceFrame::estimated;
      out.ref_from_imu = out.estimate;
      out.snap_angle_rad = 0.0;
      return out;
    }
  }
  // One frame when the IMU is mounted as the body (within the snap): nothing to tell apart.
  if (rotation_angle(imu_to_body, Matrix3d::Identity()) <= snap) {
    out.frame = ReferenceFrame::imu;
    if (out.estimate_determined) out.snap_angle_rad = rotation_angle(out.estimate, Matrix3d::Identity());
    return out;
  }
  const double better = std::min(out.misfit_as_imu_rad, out.misfit_as_body_rad);
  const double worse = std::max(out.misfit_as_imu_rad, out.misfit_as_body_rad);
  // cannot_tell (the IMU's applied) also when even the worse misfit is within a span's noise (kAlignMinSpanAngle).
  if (!(worse >= kAlignMinContrast * better) || worse < kAlignMinSpanAngle) return out;
  if (out.misfit_as_body_rad < out.misfit_as_imu_rad) {
    out.frame = ReferenceFrame::body;
    out.ref_from_imu = imu_to_body;
    if (out.estimate_determined) out.snap_angle_rad = rotation_angle(out.estimate, imu_to_body);
  } else {
    out.frame = ReferenceFrame::imu;
    if (out.estimate_determined) out.snap_angle_rad = rotation_angle(out.estimate, Matrix3d::Identity());
  }
  out.rms_misfit_rad = out.estimate_determined ? out.rms_misfit_rad : better;
  return out;
}

void rotate_to_body(ImuSeries& series, const Matrix3d& imu_to_body, const Matrix3d& ref_from_imu) {
  if (imu_to_body != Matrix3d::Identity()) {
    for (Vector3d& v : series.accel) v = imu_to_body * v;
    for (Vector3d& v : series.gyro) v = imu_to_body * v;
  }
  if (!series.reference) return;
  // q_body = q_ref * R_ref_from_imu * R_bs^T: exactly q_ref when the reference is the body's.
  if (ref_from_imu == imu_to_body) return;
  const Quaterniond m(Matrix3d(ref_from_imu * imu_to_body.transpose()));
  for (Quaterniond& q : series.reference->attitude) q = (q * m).normalized();
}

}  // namespace imubridge::estimator
