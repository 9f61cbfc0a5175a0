#include "identification/least_squares.hpp"

#include <ceres/ceres.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "estimator/constants.hpp"
#include "identification/precise_solve.hpp"

namespace imubridge::estimator {
namespace {

ceres::Solver::Options solver_options() {
  ceres::Solver::Options o;
  o.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  o.linear_solver_type = ceres::DENSE_QR;  // a handful of parameters: dense is fastest and exact
  o.max_num_iterations = 100;
  // Tight, so that LM and the GA can be compared at their optimum. The paper model starts there anyway.
  o.function_tolerance = 1e-12;
  o.gradient_tolerance = 1e-14;
  o.parameter_tolerance = 1e-12;
  o.num_threads = 1;
  o.logging_type = ceres::SILENT;
  return o;
}

SolverReport report_of(const ceres::Solver::Summary& s) {
  return {.iterations = static_cast<int>(s.iterations.size()) - 1,  // the first entry is the starting point
          .converged = s.termination_type == ceres::CONVERGENCE,
          .initial_objective = std::sqrt(2.0 * s.initial_cost),  // Ceres' cost is half the sum of squares
          .final_objective = std::sqrt(2.0 * s.final_cost),
          .message = s.message};
}

// A parameter block with the names of its coordinates and which of them the solver may change.
struct Block {
  double* data;
  std::vector<std::string> names;
  std::vector<bool> free;
};

Uncertainty uncertainty_of(ceres::Problem& problem, const std::vector<Block>& blocks) {
  Uncertainty out;
  std::vector<const double*> estimated;
  std::vector<int> free_index;  // coordinates of the free parameters in the covariance of `estimated`
  std::vector<double> values;
  int size = 0;
  for (const Block& b : blocks) {
    if (std::none_of(b.free.begin(), b.free.end(), [](bool f) { return f; })) continue;
    estimated.push_back(b.data);
    for (std::size_t i = 0; i < b.free.size(); ++i) {
      if (!b.free[i]) continue;
      free_index.push_back(size + static_cast<int>(i));
      out.names.push_back(b.names[i]);
      values.push_back(b.data[i]);
    }
    size += static_cast<int>(b.free.size());
  }
  out.value = Eigen::Map<const Eigen::VectorXd>(values.data(), static_cast<Eigen::Index>(values.size()));
  if (estimated.empty()) {
    out.failure = "no free parameters";
    return out;
  }
  const int degrees_of_freedom = problem.NumResiduals() - static_cast<int>(free_index.size());
  if (degrees_of_freedom <= 0) {
    out.failure = "no more residuals than free parameters";
    return out;
  }
  double cost = 0.0;
  problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr, nullptr);
  const double residual_variance = 2.0 * cost / degrees_of_freedom;

  ceres::Covariance::Options options;
  options.algorithm_type = ceres::DENSE_SVD;  // reports a rank-deficient Jacobian instead of returning garbage
  options.num_threads = 1;
  ceres::Covariance covariance(options);
  if (!covariance.Compute(estimated, &problem)) {
    out.failure = "the Jacobian is rank-deficient: some parameters cannot be told apart with these data";
    return out;
  }
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> all(size, size);
  covariance.GetCovarianceMatrix(estimated, all.data());
  const Eigen::MatrixXd c = residual_variance * all(free_index, free_index);
  out.std_error = c.diagonal().cwiseSqrt();
  const Eigen::VectorXd inverse = out.std_error.cwiseInverse();
  out.correlation = inverse.asDiagonal() * c * inverse.asDiagonal();
  return out;
}

// Consecutive runs of samples, one residual block each (cost_functors.hpp says why).
template <typename Sample, typename Add>
void for_each_chunk(std::span<const Sample> samples, Add add) {
  constexpr std::size_t kChunk = 64;
  for (std::size_t first = 0; first < samples.size(); first += kChunk)
    add(samples.subspan(first, std::min(kChunk, samples.size() - first)));
}

template <typename Span>
void require_samples(const Span& samples, const char* what) {
  if (samples.empty()) throw std::invalid_argument(std::string(what) + ": no samples");
}

// ---- paper model ----

void add_paper_residuals(ceres::Problem& problem, std::span<const PaperSample> samples, double* p) {
  for_each_chunk(samples, [&](std::span<const PaperSample> chunk) {
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<PaperResidual, ceres::DYNAMIC, PaperResidual::kParameters>(
                                 new PaperResidual(chunk), static_cast<int>(chunk.size())),
                             nullptr, p);
  });
  problem.SetParameterLowerBound(p, 0, 0.0);  // r
  problem.SetParameterLowerBound(p, 3, 0.0);  // mu
}

std::array<double, 4> to_array(const PaperAxisParams& p) { return {p.r, p.beta, p.alpha, p.mu}; }
PaperAxisParams from_array(const std::array<double, 4>& a) { return {a[0], a[1], a[2], a[3]}; }

// ---- 3-D model ----

constexpr int kBiasZ = 2;

std::vector<Block> add_full_residuals(ceres::Problem& problem, std::span<const FullSample> samples, FullModelParams& p,
                                      const FullHold& hold) {
  const auto data = parameter_blocks(p);
  for_each_chunk(samples, [&](std::span<const FullSample> chunk) {
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<FullResidual, ceres::DYNAMIC, 3, 3, 2, 2, 3>(
                                 new FullResidual(chunk), 2 * static_cast<int>(chunk.size())),
                             nullptr, data[0], data[1], data[2], data[3], data[4]);
  });
  std::vector<Block> blocks;
  for (int b = 0; b < kFullBlocks; ++b) {
    Block block{data[b], {}, std::vector<bool>(kFullBlockSizes[b], !hold.blocks[b])};
    for (int i = 0; i < kFullBlockSizes[b]; ++i)
      block.names.push_back(std::string(kFullBlockNames[b]) + "." + std::to_string(i));
    const auto which = static_cast<FullBlock>(b);
    if (hold.blocks[b]) {
      problem.SetParameterBlockConstant(data[b]);
    } else if (which == FullBlock::drag_linear || which == FullBlock::drag_quadratic) {
      for (int i = 0; i < kFullBlockSizes[b]; ++i) problem.SetParameterLowerBound(data[b], i, 0.0);
    } else if (which == FullBlock::accel_bias) {
      problem.SetManifold(data[b], new ceres::SubsetManifold(3, {kBiasZ}));
      block.free[kBiasZ] = false;
    }
    blocks.push_back(std::move(block));
  }
  return blocks;
}

}  // namespace

std::array<double*, kFullBlocks> parameter_blocks(FullModelParams& p) {
  return {p.lever_arm.data(), p.mounting.data(), p.drag_linear.data(), p.drag_quadratic.data(), p.accel_bias.data()};
}

PaperAxisParams paper_linear_fit(std::span<const PaperSample> samples) {
  if (samples.size() < 4) throw std::invalid_argument("paper_linear_fit: needs at least 4 samples");
  // Regressors of (g sin(alpha), r cos(beta) cos(alpha), r sin(beta) cos(alpha), mu), in eq. (14)'s signs.
  Eigen::Matrix4d gram = Eigen::Matrix4d::Zero();
  Eigen::Vector4d moment = Eigen::Vector4d::Zero();
  for (const PaperSample& s : samples) {
    const Eigen::Vector4d phi(1.0, -s.omega * s.omega, -s.omega_dot, std::abs(s.v) * s.v);
    gram.selfadjointView<Eigen::Lower>().rankUpdate(phi);
    moment += phi * s.f;
  }
  gram = gram.selfadjointView<Eigen::Lower>();
  // Columns of very different size (1, omega^2, omega_dot, v^2): equilibrate before judging the rank.
  const Eigen::Vector4d scale = gram.diagonal().cwiseSqrt();
  if ((scale.array() == 0.0).any()) throw std::invalid_argument("paper_linear_fit: a regressor is zero throughout");
  const Eigen::Matrix4d equilibrated = scale.cwiseInverse().asDiagonal() * gram * scale.cwiseInverse().asDiagonal();
  const Eigen::ColPivHouseholderQR<Eigen::Matrix4d> qr(equilibrated);
  if (qr.rank() < 4) throw std::invalid_argument("paper_linear_fit: the data do not determine eq. (14)'s terms");
  const Eigen::Vector4d c = scale.cwiseInverse().asDiagonal() * qr.solve(scale.cwiseInverse().asDiagonal() * moment);

  PaperAxisParams p;
  p.alpha = std::asin(std::clamp(c[0] / kGravity, -1.0, 1.0));
  p.r = std::hypot(c[1], c[2]) / std::cos(p.alpha);
  p.beta = std::atan2(c[2], c[1]);
  p.mu = std::max(c[3], 0.0);
  return p;
}

PaperFit fit_paper_lm(std::span<const PaperSample> samples, const PaperAxisParams& initial) {
  require_samples(samples, "fit_paper_lm");
  std::array<double, 4> p = to_array(initial);
  ceres::Problem problem;
  add_paper_residuals(problem, samples, p.data());
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options(), &problem, &summary);
  return {from_array(p), report_of(summary)};
}

Uncertainty paper_uncertainty(std::span<const PaperSample> samples, const PaperAxisParams& params) {
  require_samples(samples, "paper_uncertainty");
  std::array<double, 4> p = to_array(params);
  ceres::Problem problem;
  add_paper_residuals(problem, samples, p.data());
  return uncertainty_of(problem, {{p.data(), {"r", "beta", "alpha", "mu"}, {true, true, true, true}}});
}

FullFit fit_full_lm(std::span<const FullSample> samples, const FullModelParams& initial, const FullHold& hold) {
  require_samples(samples, "fit_full_lm");
  if (std::all_of(hold.blocks.begin(), hold.blocks.end(), [](bool h) { return h; }))
    throw std::invalid_argument("fit_full_lm: every block is held, nothing to fit");
  FullModelParams p = initial;
  ceres::Problem problem;
  add_full_residuals(problem, samples, p, hold);
  ceres::Solver::Summary summary;
  // The 3-D model's valley between its two drag laws, with one of them on its bound 0, takes LM a hundred projected
  // steps of 1e-7 of the cost each after it has converged to the 6th digit (on the real EuRoC flight: from the 4th
  // iteration on). Those decide nothing, and were nearly all of identify's time: it stops at the precision its
  // standard errors have (two residuals per sample).
  ceres::Solver::Options options = solver_options();
  options.function_tolerance = 1e-7;
  summary = solve_to_precision(problem, options, 2.0 * static_cast<double>(samples.size()));
  return {p, report_of(summary)};
}

Uncertainty full_uncertainty(std::span<const FullSample> samples, const FullModelParams& params, const FullHold& hold) {
  require_samples(samples, "full_uncertainty");
  FullModelParams p = params;
  ceres::Problem problem;
  const std::vector<Block> blocks = add_full_residuals(problem, samples, p, hold);
  return uncertainty_of(problem, blocks);
}

double full_objective(const FullModelParams& params, std::span<const FullSample> samples) {
  const Eigen::Vector2d rmse = full_rmse(params, samples);
  return std::sqrt(static_cast<double>(samples.size()) * rmse.squaredNorm());
}

Eigen::Vector2d full_rmse(const FullModelParams& p, std::span<const FullSample> samples) {
  if (samples.empty()) return Eigen::Vector2d::Zero();
  Eigen::Matrix2Xd e(2, samples.size());
  const FullResidual residual(samples);
  residual(p.lever_arm.data(), p.mounting.data(), p.drag_linear.data(), p.drag_quadratic.data(), p.accel_bias.data(),
           e.data());
  return (e.rowwise().squaredNorm() / static_cast<double>(samples.size())).cwiseSqrt();
}

}  // namespace imubridge::estimator
