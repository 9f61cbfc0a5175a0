// vibration: a sinusoid at one frequency on each diagnosed axis, the motors' or propellers' vibration (or its alias
// below the Nyquist frequency). The frequency starts at the training residual's strongest spectral line outside the
// ignored bands and is refined by the fit (docs/effects.md).
#include <Eigen/Dense>
#include <cmath>
#include <complex>
#include <numbers>

#include "diagnose/effects/library.hpp"

namespace imubridge::diagnose {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

// Power of the residuals at f, summed over axes: the periodogram the line's frequency is refined on.
double line_power(std::span<const double> t, const AxisValues& residual, double f) {
  double power = 0.0;
  for (const std::vector<double>& r : residual) {
    std::complex<double> sum = 0.0;
    for (std::size_t k = 0; k < t.size(); ++k) sum += r[k] * std::polar(1.0, -kTwoPi * f * t[k]);
    power += std::norm(sum);
  }
  return power;
}

class Vibration final : public Effect {
 public:
  std::string_view name() const override { return "vibration"; }
  Stages stages() const override { return {.prediction = true}; }
  std::optional<std::string_view> live_refusal() const override {
    return "vibration is a sinusoid whose phase belongs to the identified session's clock; live, vibration is "
           "measurement noise, which the filter's accel_noise takes from the residual RMS: re-run diagnose with "
           "--lowpass or --ignore-band";
  }
  std::vector<Parameter> parameters(const ModelSetup& setup) const override {
    const double nyquist = 0.5 * sample_rate_hz(setup.signals->t);
    std::vector<Parameter> out{{"frequency", "Hz", 0.0, 0.0, nyquist}};
    for (int axis : setup.axes) {
      out.push_back({"sin." + axis_name(axis), "m/s^2"});
      out.push_back({"cos." + axis_name(axis), "m/s^2"});
    }
    return out;
  }

  std::optional<std::string> start(const StartContext& ctx, std::span<double> p) const override {
    const double rate = sample_rate_hz(ctx.t);
    // The axes' spectra summed: a line on any axis stands out.
    Spectrum total;
    for (const std::vector<double>& r : ctx.residual) {
      const Spectrum s = welch_psd(r, rate);
      if (total.psd.empty()) {
        total = s;
      } else {
        for (std::size_t i = 0; i < s.psd.size(); ++i) total.psd[i] += s.psd[i];
      }
    }
    const std::vector<SpectralPeak> peaks = find_peaks(total, ctx.setup.ignore_bands);
    const SpectralPeak* line = nullptr;
    for (const SpectralPeak& peak : peaks) {
      if (!peak.ignored) {
        line = &peak;
        break;
      }
    }
    if (line == nullptr) return "no line in the residual's spectrum outside the ignored bands";

    // Welch's bins are far wider than the fit can start from: over T seconds a frequency off by 1/T turns the phase
    // by a full cycle. So search the periodogram around the line in steps of a tenth of 1/T.
    const double bin = total.frequency_hz[1] - total.frequency_hz[0];
    const double step = 0.1 / (ctx.t.back() - ctx.t.front());
    double best_f = line->frequency_hz, best_power = -1.0;
    for (double f = line->frequency_hz - 2.0 * bin; f <= line->frequency_hz + 2.0 * bin; f += step) {
      if (f <= 0.0) continue;
      const double power = line_power(ctx.t, ctx.residual, f);
      if (power > best_power) best_power = power, best_f = f;
    }
    p[0] = best_f;
    // The amplitudes: linear least squares at that frequency, per axis.
    for (std::size_t i = 0; i < ctx.residual.size(); ++i) {
      Eigen::Matrix2d gram = Eigen::Matrix2d::Zero();
      Eigen::Vector2d moment = Eigen::Vector2d::Zero();
      for (std::size_t k = 0; k < ctx.t.size(); ++k) {
        const Eigen::Vector2d phi(std::sin(kTwoPi * best_f * ctx.t[k]), std::cos(kTwoPi * best_f * ctx.t[k]));
        gram += phi * phi.transpose();
        moment += phi * ctx.residual[i][k];
      }
      const Eigen::Vector2d ab = gram.ldlt().solve(moment);
      p[1 + 2 * i] = ab[0];
      p[2 + 2 * i] = ab[1];
    }
    return std::nullopt;
  }

  void add_prediction(std::span<const double> p, const PredictionContext& ctx, AxisValues& prediction) const override {
    const std::vector<double>& t = ctx.setup.signals->t;
    for (std::size_t k = 0; k < ctx.count; ++k) {
      const double phase = kTwoPi * p[0] * t[ctx.first + k];
      const double s = std::sin(phase), c = std::cos(phase);
      for (std::size_t i = 0; i < prediction.size(); ++i) prediction[i][k] += p[1 + 2 * i] * s + p[2 + 2 * i] * c;
    }
  }
};

}  // namespace

std::unique_ptr<Effect> make_vibration() { return std::make_unique<Vibration>(); }

}  // namespace imubridge::diagnose
