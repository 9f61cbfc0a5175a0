#pragma once
// Horizontal drag per body axis, as a specific force: f = -k*v - mu*|v|*v (docs/model.md). k is the linear
// rotor/momentum drag (1/s), mu the paper's quadratic term (1/m), v the body-axis air velocity (m/s).
#include <cmath>
#include <limits>

namespace imubridge::estimator {

// Templated on the parameters so Ceres can differentiate it; the velocity is data.
template <typename T>
T drag_specific_force(const T& k, const T& mu, double v) {
  return -(k * v + mu * (std::abs(v) * v));
}

// |df/dv| = k + 2*mu*|v|: turns accelerometer noise into velocity noise when the law is inverted.
inline double drag_slope(double k, double mu, double v) { return k + 2.0 * mu * std::abs(v); }

// The velocity whose drag is f. With k, mu >= 0 and k + mu > 0 the law is odd and strictly decreasing, so the root
// of mu*|v|*v + k*v = -f is unique: |v| = 2|f| / (k + sqrt(k^2 + 4*mu*|f|)), the form that stays exact when mu or k
// is zero. NaN when k = mu = 0 (no drag, nothing to invert).
inline double invert_drag(double k, double mu, double f) {
  if (!(k + mu > 0.0)) return std::numeric_limits<double>::quiet_NaN();
  const double s = std::abs(f);
  if (s == 0.0) return 0.0;  // the formula's 0/0 when k = 0
  const double speed = 2.0 * s / (k + std::sqrt(k * k + 4.0 * mu * s));
  return f > 0.0 ? -speed : speed;
}

}  // namespace imubridge::estimator
