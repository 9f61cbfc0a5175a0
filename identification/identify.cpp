#include "identification/identify.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <atomic>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <utility>

#include "estimator/constants.hpp"
#include "estimator/on_threads.hpp"
#include "estimator/velocity.hpp"

namespace imubridge::estimator {
namespace {

constexpr double kDegree = kPi / 180.0;

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// The end of the data: the last sample's time plus its period, so that [start, end) holds the last sample.
double data_end(std::span<const double> t) { return t.size() > 1 ? 2.0 * t.back() - t[t.size() - 2] : t.back(); }

void require_reference(const ImuSeries& series, const char* what) {
  if (!series.reference) throw std::invalid_argument(std::string(what) + " needs a reference trajectory");
}

// The reference's velocity in body axes.
std::vector<Eigen::Vector3d> reference_body_velocity(const ImuSeries& series) {
  return body_velocity(series.reference->attitude, series.reference->velocity_ned);
}

// Eq. (12)'s 3-D generalisation: gyro-integrated attitude, thrust g along -z_b, no drag; body-axis velocity.
std::vector<Eigen::Vector3d> dead_reckoned_body_velocity(std::span<const double> t,
                                                         std::span<const Eigen::Vector3d> gyro_body) {
  const std::vector<double> thrust(t.size(), kGravity);
  const DeadReckoning dr = dead_reckon(t, gyro_body, thrust);
  return body_velocity(dr.attitude, dr.velocity_ned);
}

// The slope of a least-squares polynomial (degree <= 3) through the samples within +-half_window of each sample,
// in the local time u = (t_j - t_k) / half_window, which keeps the normal equations well conditioned: of samples
// [begin, end), into out. [first, last) is a window found for an earlier sample (or 0, 0), where the search for
// begin's window starts.
template <typename Value>
void cubic_slope_of(std::span<const double> t, std::span<const Value> x, double half_window, std::size_t begin,
                    std::size_t end, std::size_t& first, std::size_t& last, std::vector<Value>& out) {
  constexpr int kMaxDegree = 3;
  for (std::size_t k = begin; k < end; ++k) {
    while (t[k] - t[first] > half_window) ++first;
    while (last < t.size() && t[last] - t[k] <= half_window) ++last;
    const int degree = std::min(kMaxDegree, static_cast<int>(last - first) - 1);
    if (degree < 1) continue;  // a lone sample: no slope to be had
    Eigen::Matrix4d gram = Eigen::Matrix4d::Zero();
    Eigen::Matrix<double, 4, Value::RowsAtCompileTime> moment =
        Eigen::Matrix<double, 4, Value::RowsAtCompileTime>::Zero();
    for (std::size_t j = first; j < last; ++j) {
      const double u = (t[j] - t[k]) / half_window;
      const Eigen::Vector4d powers(1.0, u, u * u, u * u * u);
      gram += powers * powers.transpose();
      moment += powers * x[j].transpose();
    }
    const int n = degree + 1;
    const Eigen::MatrixXd c = gram.topLeftCorner(n, n).ldlt().solve(moment.topRows(n));
    out[k] = c.row(1).transpose() / half_window;
  }
}

template <typename Value>
std::vector<Value> cubic_slope(std::span<const double> t, std::span<const Value> x, double half_window) {
  if (t.size() != x.size()) throw std::invalid_argument("smoothed_derivative: t and x lengths differ");
  if (!(half_window > 0.0)) throw std::invalid_argument("smoothed_derivative: the half window must be positive");
  std::vector<Value> out(t.size(), Value::Zero());
  // Each sample's fit is its own, so a flight's are shared among the cores (a tenth of identify's time on one): the
  // threads take runs of samples as they come free, and the numbers are the same however they were shared. A thread's
  // runs come in time order, so its window's search goes on from its previous run's.
  constexpr std::size_t kPerRun = 4096;
  std::atomic<std::size_t> next{0};
  on_threads(std::min<std::size_t>(cores(), (t.size() + kPerRun - 1) / kPerRun), [&](std::size_t) {
    std::size_t first = 0, last = 0;
    for (std::size_t begin = next.fetch_add(kPerRun); begin < t.size(); begin = next.fetch_add(kPerRun))
      cubic_slope_of(t, x, half_window, begin, std::min(begin + kPerRun, t.size()), first, last, out);
  });
  return out;
}

std::vector<double> column(std::span<const PaperSample> samples, double PaperSample::*field) {
  std::vector<double> out;
  out.reserve(samples.size());
  for (const PaperSample& s : samples) out.push_back(s.*field);
  return out;
}

void record_uncertainty(const FitReport& report, Identification& id) {
  const Uncertainty& u = report.uncertainty;
  if (!u.failure.empty()) return;  // no standard errors to record
  for (std::size_t i = 0; i < u.names.size(); ++i)
    id.std_errors[report.name + "." + u.names[i]] = u.std_error[static_cast<Eigen::Index>(i)];
}

double wrap_angle(double a) { return std::remainder(a, 2.0 * kPi); }

FitReport identify_paper_axis(const std::vector<PaperSample>& samples, const Windows& w, const IdentifyOptions& o,
                              const std::string& name, PaperAxisParams& p, Identification& id) {
  const std::span<const PaperSample> fit = select(samples, w.train);
  const std::span<const PaperSample> validation = select(samples, w.validate);
  FitReport report{.name = name, .fit_samples = fit.size(), .validation_samples = validation.size()};
  const auto start = std::chrono::steady_clock::now();
  if (o.method != Method::lm) {
    const GaResult ga = minimize_ga(
        [fit](std::span<const double> g) {
          return objective({g[0], g[1], g[2], g[3]}, fit);
        },
        paper_bounds(), o.ga);
    p = {ga.best[0], ga.best[1], ga.best[2], ga.best[3]};
    report.convergence = ga.convergence;
  }
  if (o.method != Method::ga) {
    const PaperFit lm = fit_paper_lm(fit, o.method == Method::lm ? paper_linear_fit(fit) : p);
    p = lm.params;
    p.beta = wrap_angle(p.beta);
    report.lm = lm.report;
  }
  report.solve_seconds = seconds_since(start);
  report.fit_objective = objective(p, fit);
  report.uncertainty = paper_uncertainty(fit, p);
  id.rmse[name + ".fit"] = rmse(p, fit);
  id.rmse[name + ".validation"] = rmse(p, validation);
  record_uncertainty(report, id);
  return report;
}

// One coordinate of FullModelParams that the GA searches, with its box.
struct Gene {
  int block, index;
  double lower, upper;
};

std::vector<Gene> full_genes(const FullHold& hold) {
  // Generous for a small multirotor: IMU within 0.5 m of the mass centre, mounted within 11 degrees of the body
  // axes, drag well beyond the paper's, accelerometer bias within 0.2 g.
  constexpr std::array<std::pair<double, double>, kFullBlocks> kBox{
      {{-0.5, 0.5}, {-0.2, 0.2}, {0.0, 2.0}, {0.0, 1.0}, {-2.0, 2.0}}};
  std::vector<Gene> genes;
  for (int b = 0; b < kFullBlocks; ++b) {
    if (hold.blocks[b]) continue;
    // The bias's z is held (least_squares.hpp).
    const int size = static_cast<FullBlock>(b) == FullBlock::accel_bias ? 2 : kFullBlockSizes[b];
    for (int i = 0; i < size; ++i) genes.push_back({b, i, kBox[b].first, kBox[b].second});
  }
  return genes;
}

FullModelParams from_genes(std::span<const double> g, const std::vector<Gene>& genes, FullModelParams p) {
  const auto blocks = parameter_blocks(p);
  for (std::size_t i = 0; i < genes.size(); ++i) blocks[genes[i].block][genes[i].index] = g[i];
  return p;
}

FitReport identify_full(const std::vector<FullSample>& samples, const Windows& w, const IdentifyOptions& o,
                        FullModelParams& p, Identification& id) {
  const std::span<const FullSample> fit = select(samples, w.train);
  const std::span<const FullSample> validation = select(samples, w.validate);
  FitReport report{.name = "full", .fit_samples = fit.size(), .validation_samples = validation.size()};
  const auto start = std::chrono::steady_clock::now();
  p = FullModelParams{};  // LM starts with the IMU at the mass centre, aligned, no drag, no bias
  if (o.method != Method::lm) {
    const std::vector<Gene> genes = full_genes(o.hold);
    GaBounds bounds;
    for (const Gene& gene : genes) {
      bounds.lower.push_back(gene.lower);
      bounds.upper.push_back(gene.upper);
    }
    const GaResult ga = minimize_ga(
        [&](std::span<const double> g) { return full_objective(from_genes(g, genes, p), fit); }, bounds, o.ga);
    p = from_genes(ga.best, genes, p);
    report.convergence = ga.convergence;
  }
  if (o.method != Method::ga) {
    const FullFit lm = fit_full_lm(fit, p, o.hold);
    p = lm.params;
    report.lm = lm.report;
  }
  report.solve_seconds = seconds_since(start);
  report.fit_objective = full_objective(p, fit);
  report.uncertainty = full_uncertainty(fit, p, o.hold);
  const Eigen::Vector2d fit_rmse = full_rmse(p, fit), validation_rmse = full_rmse(p, validation);
  id.rmse["full.x.fit"] = fit_rmse.x();
  id.rmse["full.y.fit"] = fit_rmse.y();
  id.rmse["full.x.validation"] = validation_rmse.x();
  id.rmse["full.y.validation"] = validation_rmse.y();
  record_uncertainty(report, id);
  return report;
}

}  // namespace

TimeWindow clip(const TimeWindow& w, std::span<const double> t, const char* what) {
  const TimeWindow clipped{std::max(w.start, t.front()), std::min(w.end, data_end(t))};
  const auto first = std::lower_bound(t.begin(), t.end(), clipped.start);
  if (!(clipped.start < clipped.end) || first == t.end() || !(*first < clipped.end)) {
    char message[200];
    std::snprintf(message, sizeof message, "%s window %.3f:%.3f s holds no data (the data span %.3f:%.3f s)", what,
                  w.start, w.end, t.front(), data_end(t));
    throw std::invalid_argument(message);
  }
  return clipped;
}

TimeWindow data_span(std::span<const double> t) {
  if (t.empty()) throw std::invalid_argument("no samples");
  return {t.front(), data_end(t)};
}

TimeWindow parse_window(std::string_view text, std::span<const double> t) {
  return t.empty() ? parse_window(text, TimeWindow{0.0, 0.0}) : parse_window(text, data_span(t));
}

TimeWindow parse_window(std::string_view text, const TimeWindow& span) {
  const bool has_span = span.start < span.end;
  bool needs_span = false;
  // Seconds, or percentages (0 to 100) of the span from its start: one "%" makes both ends percentages, so that
  // "0:40%" is the first 40 %.
  const bool percent = text.find('%') != std::string_view::npos;
  const auto number = [&](std::string_view piece, double& x) {
    if (percent && !piece.empty() && piece.back() == '%') piece.remove_suffix(1);
    const auto [end, error] = std::from_chars(piece.data(), piece.data() + piece.size(), x);
    if (error != std::errc() || end != piece.data() + piece.size() || !std::isfinite(x)) return false;
    if (!percent) return true;
    if (x < 0.0 || x > 100.0) return false;
    if (!has_span) return needs_span = true;
    x = span.start + x / 100.0 * (span.end - span.start);
    return true;
  };
  const std::size_t colon = text.find(':');
  TimeWindow w{0.0, std::numeric_limits<double>::infinity()};
  // In percent, an open end is the span's end (100 %): with --in-flight, "40%:" ends where the flight does.
  if (percent && has_span) w.end = span.end;
  const bool ok = colon != std::string_view::npos && number(text.substr(0, colon), w.start) &&
                  (colon + 1 == text.size() || number(text.substr(colon + 1), w.end)) &&
                  (needs_span || w.start < w.end);
  if (!ok)
    throw std::invalid_argument("bad window \"" + std::string(text) +
                                "\": expected T0:T1 (or T0: to the end), each in seconds or as a percentage of the "
                                "data (0:40%, 40%:), T0 < T1");
  if (needs_span) throw std::invalid_argument("window \"" + std::string(text) + "\": a percentage needs the data");
  return w;
}

Windows resolve_windows(std::span<const double> t, const std::optional<TimeWindow>& train,
                        const std::optional<TimeWindow>& validate) {
  if (t.empty()) throw std::invalid_argument("no samples to identify from");
  constexpr double kForever = std::numeric_limits<double>::infinity();
  const TimeWindow train_window = train.value_or(TimeWindow{0.0, kPaperTrainSeconds});
  const TimeWindow validate_window = validate.value_or(TimeWindow{train_window.end, kForever});
  return {clip(train_window, t, "training"), clip(validate_window, t, "validation")};
}

void require_trainable(const TimeWindow& train) {
  const double length = train.end - train.start;
  if (length >= kMinTrainSeconds) return;
  char text[240];
  std::snprintf(text, sizeof text,
                "the training window %.2f:%.2f s holds %.1f s of data; identifying the drag needs at least %g s (a "
                "multirotor's velocity answers a tilt within about 3/k): give a longer --train",
                train.start, train.end, length, kMinTrainSeconds);
  throw std::invalid_argument(text);
}

std::vector<Eigen::Vector3d> smoothed_derivative(std::span<const double> t, std::span<const Eigen::Vector3d> x,
                                                 double half_window) {
  return cubic_slope(t, x, half_window);
}

std::vector<PaperSample> prepare_paper(const ImuSeries& series, PaperAxis axis, VelocitySource velocity,
                                       double half_window) {
  std::vector<PaperSample> samples = prepare_paper_axis(series, axis);
  // omega is already in the axis's frame (roll: -omega_x), so its derivative needs no mapping of its own.
  const std::vector<double> t = column(samples, &PaperSample::t);
  std::vector<Eigen::Matrix<double, 1, 1>> omega(samples.size());
  for (std::size_t k = 0; k < samples.size(); ++k) omega[k][0] = samples[k].omega;
  const auto omega_dot = cubic_slope<Eigen::Matrix<double, 1, 1>>(t, omega, half_window);
  for (std::size_t k = 0; k < samples.size(); ++k) samples[k].omega_dot = omega_dot[k][0];
  if (velocity == VelocitySource::reference) {
    require_reference(series, "velocity from the reference");
    // The axis's x' is x_b for pitch and y_b for roll; the paper's v is minus the velocity along it.
    const int along = axis == PaperAxis::pitch ? 0 : 1;
    const std::vector<Eigen::Vector3d> v_body = reference_body_velocity(series);
    for (std::size_t k = 0; k < samples.size(); ++k) samples[k].v = -v_body[k][along];
  }
  return samples;
}

std::vector<FullSample> prepare_full(const ImuSeries& series, VelocitySource velocity, double half_window) {
  require_valid(series);
  const std::vector<Eigen::Vector3d> gyro_rate = smoothed_derivative(series.t, series.gyro, half_window);
  std::vector<Eigen::Vector3d> v_body;
  if (velocity == VelocitySource::reference) {
    require_reference(series, "velocity from the reference");
    v_body = reference_body_velocity(series);
  } else {
    v_body = dead_reckoned_body_velocity(series.t, series.gyro);  // the mounting is not known yet: gyro as body
  }
  std::vector<FullSample> samples(series.size());
  for (std::size_t k = 0; k < samples.size(); ++k)
    samples[k] = {series.t[k], series.gyro[k], gyro_rate[k], series.accel[k], v_body[k].head<2>()};
  return samples;
}

GaBounds paper_bounds() { return {{0.0, -kPi, -15.0 * kDegree, 0.0}, {0.5, kPi, 15.0 * kDegree, 1.0}}; }

FullModelParams full_from_paper(const PaperAxisParams& pitch, const PaperAxisParams& roll) {
  FullModelParams p;
  // Pitch: the IMU at r (cos b, 0, -sin b); roll: at r (0, cos b, -sin b). Both see the height; take the mean.
  p.lever_arm = {pitch.r * std::cos(pitch.beta), roll.r * std::cos(roll.beta),
                 -0.5 * (pitch.r * std::sin(pitch.beta) + roll.r * std::sin(roll.beta))};
  p.mounting = {-roll.alpha, pitch.alpha, 0.0};
  p.drag_quadratic = {pitch.mu, roll.mu};
  return p;
}

double eq12_drift(const ImuSeries& series, const Eigen::Vector3d& mounting, const TimeWindow& window) {
  require_valid(series);
  FullModelParams rotation_only;
  rotation_only.mounting = mounting;
  const LeverArmCompensator imu_to_body(rotation_only);
  std::vector<Eigen::Vector3d> gyro_body(series.size());
  for (std::size_t k = 0; k < series.size(); ++k) gyro_body[k] = imu_to_body.to_body(series.gyro[k]);
  const DeadReckoning dr = dead_reckon(series.t, gyro_body, std::vector<double>(series.size(), kGravity));
  // The line v = a + b t per horizontal axis, in time relative to the window's start.
  Eigen::Matrix2d gram = Eigen::Matrix2d::Zero();
  Eigen::Matrix2d moment = Eigen::Matrix2d::Zero();  // columns: north, east
  for (std::size_t k = 0; k < series.size(); ++k) {
    if (series.t[k] < window.start || !(series.t[k] < window.end)) continue;
    const Eigen::Vector2d phi(1.0, series.t[k] - window.start);
    gram += phi * phi.transpose();
    moment += phi * dr.velocity_ned[k].head<2>().transpose();
  }
  if (gram(0, 0) < 2.0 || !(gram.determinant() > 0.0)) return 0.0;
  const Eigen::Matrix2d line = gram.ldlt().solve(moment);  // rows: a, b
  const double span = std::min(window.end, data_end(series.t)) - window.start;
  return line.row(1).norm() * span;
}

std::optional<std::string> eq12_drift_warning(const ImuSeries& series, const Eigen::Vector3d& mounting,
                                              const TimeWindow& window) {
  const double drift = eq12_drift(series, mounting, window);
  if (!(drift > kEq12DriftLimit)) return std::nullopt;
  char text[320];
  std::snprintf(text, sizeof text,
                "eq. (12)'s velocity drifts by %.3g m/s over the training window (more than %g m/s): it is the "
                "integral's error, not the flight's velocity, and a drag fitted to it fits the drift; use "
                "--velocity filter",
                drift, kEq12DriftLimit);
  return text;
}

IdentifyResult identify(const ImuSeries& series, const IdentifyOptions& o) {
  require_valid(series);
  if (o.velocity == VelocitySource::reference) require_reference(series, "velocity from the reference");
  if (o.velocity == VelocitySource::filter)
    throw std::invalid_argument("identify: the filter's velocity is fitted by diagnose::identify_by_filter_error");
  if (o.model == ModelKind::full && std::all_of(o.hold.blocks.begin(), o.hold.blocks.end(), [](bool h) { return h; }))
    throw std::invalid_argument("every block of the 3-D model is held: nothing to identify");
  const Windows windows = resolve_windows(series.t, o.train, o.validate);
  require_trainable(windows.train);
  IdentifyResult result;
  Identification& id = result.params.identification;
  id.method = name(o.method);
  id.seed = o.method == Method::lm ? 0 : o.ga.seed;
  id.fit_windows = {windows.train};
  id.validation_windows = {windows.validate};
  if (o.model == ModelKind::paper) {
    for (const PaperAxis axis : {PaperAxis::pitch, PaperAxis::roll}) {
      const bool pitch = axis == PaperAxis::pitch;
      PaperAxisParams& p = pitch ? result.params.paper_x : result.params.paper_y;
      const auto samples = prepare_paper(series, axis, o.velocity, o.derivative_half_window);
      result.fits.push_back(identify_paper_axis(samples, windows, o, pitch ? "paper.x" : "paper.y", p, id));
    }
    result.params.full = full_from_paper(result.params.paper_x, result.params.paper_y);
  } else {
    const auto samples = prepare_full(series, o.velocity, o.derivative_half_window);
    result.fits.push_back(identify_full(samples, windows, o, result.params.full, id));
  }
  return result;
}

std::vector<VelocityEvaluation> evaluate_velocity(const ImuSeries& series, const FullModelParams& params,
                                                  std::span<const TimeWindow> windows,
                                                  const DragVelocityConfig& config) {
  require_valid(series);
  require_reference(series, "evaluating the velocity");
  if (series.size() == 0) throw std::invalid_argument("no samples to evaluate");
  DragVelocityEstimator estimator(params, config);
  // An axis without drag reads rest when the other has one (DragVelocityEstimator): scored as such, as the anchor
  // scores an axis where it reads no drag.
  if (!estimator.has_drag(0) && !estimator.has_drag(1))
    throw std::invalid_argument("evaluating the velocity needs drag identified on a horizontal axis");
  std::vector<VelocityEvaluation> out(windows.size());
  for (std::size_t w = 0; w < windows.size(); ++w) out[w].window = clip(windows[w], series.t, "evaluation");

  const LeverArmCompensator imu_to_body(params);  // for its mounting rotation
  // The estimator's velocity is in its body frame, the one the mounting defines (R_bs: IMU -> body); the reference's
  // body-axis velocity is in the series' axes. Score like with like: the truth turned by R_bs.
  std::vector<Eigen::Vector3d> truth = reference_body_velocity(series);
  for (Eigen::Vector3d& v : truth) v = imu_to_body.to_body(v);
  std::vector<Eigen::Vector3d> gyro_body(series.size());
  for (std::size_t k = 0; k < series.size(); ++k) gyro_body[k] = imu_to_body.to_body(series.gyro[k]);
  const std::vector<Eigen::Vector3d> open_loop = dead_reckoned_body_velocity(series.t, gyro_body);

  struct Sums {
    VelocityErrorSum filter, inversion, eq12, zero;
    double nees = 0.0;
    double block = -1.0, gain = 0.0, gain_samples = 0.0;  // the gain over zero velocity's block being summed
    void close_block(std::vector<double>& blocks) {
      if (gain_samples > 0.0) blocks.push_back(gain / gain_samples);
      gain = gain_samples = 0.0;
    }
  };
  std::vector<Sums> sums(windows.size());
  LandedCursor landed(series.landed);
  for (std::size_t k = 0; k < series.size(); ++k) {
    estimator.set_landed(landed.at(series.t[k]));
    const std::optional<DragVelocityEstimate> e = estimator.update(series.sample(k));
    if (!e) continue;
    // The estimate describes an earlier sample (the differentiator's delay): score it against that one.
    const auto i =
        static_cast<std::size_t>(std::lower_bound(series.t.begin(), series.t.end(), e->t) - series.t.begin());
    const Eigen::Vector2d v = truth[i].head<2>();
    for (std::size_t w = 0; w < windows.size(); ++w) {
      if (e->t < out[w].window.start || !(e->t < out[w].window.end)) continue;
      sums[w].filter.add(e->v - v);
      sums[w].inversion.add(e->v_raw - v);
      sums[w].eq12.add(open_loop[i].head<2>() - v);
      sums[w].zero.add(-v);
      sums[w].nees += (e->v - v).cwiseAbs2().cwiseQuotient(e->v_var).sum();
      const double block = std::floor((e->t - out[w].window.start) / kGainBlockSeconds);
      if (block != sums[w].block) sums[w].close_block(out[w].gain_over_zero), sums[w].block = block;
      sums[w].gain += v.squaredNorm() - (e->v - v).squaredNorm();
      sums[w].gain_samples += 1.0;
      ++out[w].samples;
    }
  }
  for (std::size_t w = 0; w < windows.size(); ++w) {
    if (out[w].samples == 0) throw std::invalid_argument("no estimates inside the evaluation window");
    sums[w].close_block(out[w].gain_over_zero);
    out[w].estimator = sums[w].filter.rmse();
    out[w].estimator_mean_error = sums[w].filter.mean();
    out[w].estimator_constant_known = sums[w].filter.rmse_about_mean();
    out[w].inversion = sums[w].inversion.rmse();
    out[w].eq12 = sums[w].eq12.rmse();
    out[w].zero = sums[w].zero.rmse();
    out[w].nees = sums[w].nees / static_cast<double>(out[w].samples);
    out[w].counters = estimator.counters();
  }
  return out;
}

VelocityEvaluation evaluate_velocity(const ImuSeries& series, const FullModelParams& params,
                                     const std::optional<TimeWindow>& window, const DragVelocityConfig& config) {
  if (series.size() == 0) throw std::invalid_argument("no samples to evaluate");
  const TimeWindow w = window.value_or(TimeWindow{series.t.front(), data_end(series.t)});
  return evaluate_velocity(series, params, std::span<const TimeWindow>(&w, 1), config).front();
}

}  // namespace imubridge::estimator
