#pragma once
// The paper's single-axis accelerometer model, eq. (8)-(15) of Khorani & Shahri 2013, in the conventions of
// docs/model.md. The x (pitch) axis is the paper's. The y (roll) axis is the same model in a body frame turned
// +90 deg about z_b (x' = y_b, y' = -x_b), where omega_y' = -omega_x, f_x' = f_y and theta' = -phi.
#include <cmath>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "estimator/constants.hpp"
#include "estimator/imu_series.hpp"

namespace imubridge::estimator {

// One axis's parameters. The defaults are the paper's precise installation (r, beta, alpha) = (0, pi/2, 0) without
// drag: the model then predicts zero.
struct PaperAxisParams {
  double r = 0.0;           // m, distance of the IMU from the mass centre
  double beta = kPi / 2.0;  // rad, direction of the IMU from x_b toward -z_b (from y_b toward -z_b for roll)
  double alpha = 0.0;       // rad, tilt of the sensor's x axis about y_b (of its y axis about -x_b for roll)
  double mu = 0.0;          // 1/m, quadratic drag

  friend bool operator==(const PaperAxisParams&, const PaperAxisParams&) = default;
};

// Why `p` is unusable (a non-finite value, negative r or mu: beta carries the direction), or nullopt.
std::optional<std::string> validate(const PaperAxisParams& p);

// Eq. (14) is linear in four combinations of the parameters. Computing them once per parameter set keeps a GA
// objective to a few multiply-adds per sample. T is double or a ceres::Jet.
template <typename T>
struct PaperCoefficients {
  T g_sin_alpha;  // thrust (U1 ~ g) seen through the tilted sensor axis
  T centripetal;  // r cos(beta) cos(alpha), multiplies omega^2
  T tangential;   // r sin(beta) cos(alpha), multiplies omega_dot
  T mu;           // multiplies sign(v) v^2
};

template <typename T>
PaperCoefficients<T> paper_coefficients(const T& r, const T& beta, const T& alpha, const T& mu) {
  using std::cos;
  using std::sin;
  return {kGravity * sin(alpha), r * cos(beta) * cos(alpha), r * sin(beta) * cos(alpha), mu};
}

inline PaperCoefficients<double> paper_coefficients(const PaperAxisParams& p) {
  return paper_coefficients(p.r, p.beta, p.alpha, p.mu);
}

// The per-sample signals of eq. (14); none depends on the parameters, so they are computed once per data set.
struct PaperSample {
  double t = 0.0;          // s
  double omega = 0.0;      // rad/s: omega_y (pitch) or -omega_x (roll)
  double omega_dot = 0.0;  // rad/s^2
  double theta = 0.0;      // rad, eq. (11)
  double v = 0.0;          // m/s, eq. (12), the paper's sign (minus the NED velocity)
  double f = 0.0;          // m/s^2, measured specific force: f_x (pitch) or f_y (roll)
};

// Eq. (14): f_bar = g sin(alpha) - r (omega^2 cos(beta) + omega_dot sin(beta)) cos(alpha) + mu sign(v) v^2.
template <typename T>
T paper_specific_force(const PaperCoefficients<T>& c, const PaperSample& s) {
  return c.g_sin_alpha - (c.centripetal * (s.omega * s.omega) + c.tangential * s.omega_dot) +
         c.mu * (std::abs(s.v) * s.v);
}

enum class PaperAxis { pitch, roll };

// One axis's signals from an IMU series: theta and v by eq. (11)-(12) (trapezoidal rule, theta0 = v0 = 0) and
// omega_dot by the central difference (offline, no delay). Throws std::invalid_argument for an invalid series.
std::vector<PaperSample> prepare_paper_axis(const ImuSeries& series, PaperAxis axis);

// f_bar per sample.
std::vector<double> predict(const PaperAxisParams& p, std::span<const PaperSample> samples);
// Eq. (15): OF = sqrt(sum over samples of (f - f_bar)^2), m/s^2.
double objective(const PaperAxisParams& p, std::span<const PaperSample> samples);
// OF / sqrt(n); 0 for no samples.
double rmse(const PaperAxisParams& p, std::span<const PaperSample> samples);

}  // namespace imubridge::estimator
