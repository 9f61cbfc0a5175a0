#include "estimator/paper_model.hpp"

#include "estimator/differentiator.hpp"
#include "estimator/velocity.hpp"

namespace imubridge::estimator {

std::optional<std::string> validate(const PaperAxisParams& p) {
  if (!std::isfinite(p.r) || !std::isfinite(p.beta) || !std::isfinite(p.alpha) || !std::isfinite(p.mu))
    return "non-finite parameter";
  if (p.r < 0.0 || p.mu < 0.0) return "negative r or mu";
  return std::nullopt;
}

std::vector<PaperSample> prepare_paper_axis(const ImuSeries& series, PaperAxis axis) {
  require_valid(series);
  const std::size_t n = series.size();
  const std::vector<Eigen::Vector3d> gyro_rate = central_difference(series.t, series.gyro);
  // The roll axis is the pitch model in a body frame turned +90 deg about z_b: omega' = -omega_x, f' = f_y.
  const bool pitch = axis == PaperAxis::pitch;
  std::vector<double> omega(n);
  for (std::size_t k = 0; k < n; ++k) omega[k] = pitch ? series.gyro[k].y() : -series.gyro[k].x();
  const PitchIntegration integrated = integrate_pitch(series.t, omega);

  std::vector<PaperSample> samples(n);
  for (std::size_t k = 0; k < n; ++k) {
    samples[k] = {.t = series.t[k],
                  .omega = omega[k],
                  .omega_dot = pitch ? gyro_rate[k].y() : -gyro_rate[k].x(),
                  .theta = integrated.theta[k],
                  .v = integrated.v[k],
                  .f = pitch ? series.accel[k].x() : series.accel[k].y()};
  }
  return samples;
}

std::vector<double> predict(const PaperAxisParams& p, std::span<const PaperSample> samples) {
  const PaperCoefficients<double> c = paper_coefficients(p);
  std::vector<double> f(samples.size());
  for (std::size_t k = 0; k < samples.size(); ++k) f[k] = paper_specific_force(c, samples[k]);
  return f;
}

double objective(const PaperAxisParams& p, std::span<const PaperSample> samples) {
  const PaperCoefficients<double> c = paper_coefficients(p);
  double sum = 0.0;
  for (const PaperSample& s : samples) {
    const double e = s.f - paper_specific_force(c, s);
    sum += e * e;
  }
  return std::sqrt(sum);
}

double rmse(const PaperAxisParams& p, std::span<const PaperSample> samples) {
  return samples.empty() ? 0.0 : objective(p, samples) / std::sqrt(static_cast<double>(samples.size()));
}

}  // namespace imubridge::estimator
