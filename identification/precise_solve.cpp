#include "identification/precise_solve.hpp"

#include <ceres/crs_matrix.h>
#include <ceres/manifold.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace imubridge::estimator {
namespace {

bool on_bound(double value, double bound) {
  return std::isfinite(bound) && std::abs(bound) < std::numeric_limits<double>::max() &&
         std::abs(value - bound) <= 1e-12 * std::max(1.0, std::abs(bound));
}

}  // namespace

double gauss_newton_relative_decrease(ceres::Problem& problem) {
  std::vector<double*> blocks;
  problem.GetParameterBlocks(&blocks);
  ceres::Problem::EvaluateOptions evaluate;
  evaluate.parameter_blocks = blocks;
  double cost = 0.0;
  std::vector<double> gradient;
  ceres::CRSMatrix jacobian;
  if (!problem.Evaluate(evaluate, &cost, nullptr, &gradient, &jacobian) || !(cost > 0.0)) return 0.0;

  // The tangent columns that may move: not in a constant block, not a coordinate pinned on its bound.
  std::vector<int> free;
  int column = 0;
  for (double* block : blocks) {
    const int size = problem.ParameterBlockSize(block), tangent = problem.ParameterBlockTangentSize(block);
    if (problem.IsParameterBlockConstant(block)) {
      column += tangent;
      continue;
    }
    // Which ambient coordinate each tangent column moves (a selection, as SubsetManifold's); -1 for a mixture.
    std::vector<int> coordinate(static_cast<std::size_t>(tangent), -1);
    if (const ceres::Manifold* manifold = problem.GetManifold(block)) {
      std::vector<double> plus(static_cast<std::size_t>(size * tangent));
      manifold->PlusJacobian(block, plus.data());
      for (int j = 0; j < tangent; ++j) {
        int nonzero = 0, row = -1;
        for (int i = 0; i < size; ++i) {
          if (plus[static_cast<std::size_t>(i * tangent + j)] != 0.0) ++nonzero, row = i;
        }
        if (nonzero == 1) coordinate[static_cast<std::size_t>(j)] = row;
      }
    } else {
      for (int j = 0; j < tangent; ++j) coordinate[static_cast<std::size_t>(j)] = j;
    }
    for (int j = 0; j < tangent; ++j) {
      const int i = coordinate[static_cast<std::size_t>(j)];
      const bool pinned = i >= 0 && (on_bound(block[i], problem.GetParameterLowerBound(block, i)) ||
                                     on_bound(block[i], problem.GetParameterUpperBound(block, i)));
      if (!pinned) free.push_back(column + j);
    }
    column += tangent;
  }
  if (free.empty()) return 0.0;

  Eigen::MatrixXd j = Eigen::MatrixXd::Zero(jacobian.num_rows, static_cast<Eigen::Index>(free.size()));
  std::vector<int> position(static_cast<std::size_t>(jacobian.num_cols), -1);
  for (std::size_t f = 0; f < free.size(); ++f) position[static_cast<std::size_t>(free[f])] = static_cast<int>(f);
  for (int r = 0; r < jacobian.num_rows; ++r) {
    for (int k = jacobian.rows[static_cast<std::size_t>(r)]; k < jacobian.rows[static_cast<std::size_t>(r) + 1]; ++k) {
      const int p = position[static_cast<std::size_t>(jacobian.cols[static_cast<std::size_t>(k)])];
      if (p >= 0) j(r, p) = jacobian.values[static_cast<std::size_t>(k)];
    }
  }
  Eigen::VectorXd g(static_cast<Eigen::Index>(free.size()));
  for (std::size_t f = 0; f < free.size(); ++f)
    g[static_cast<Eigen::Index>(f)] = gradient[static_cast<std::size_t>(free[f])];
  const Eigen::MatrixXd h = j.transpose() * j;
  const Eigen::VectorXd step = h.completeOrthogonalDecomposition().solve(g);
  return 0.5 * g.dot(step) / cost;
}

ceres::Solver::Summary solve_to_precision(ceres::Problem& problem, const ceres::Solver::Options& options,
                                          double independent_residuals) {
  const double precision =
      kPrecisionInStandardErrors * kPrecisionInStandardErrors / std::max(independent_residuals, 1.0);
  ceres::Solver::Options loose = options;
  loose.function_tolerance = std::clamp(precision, options.function_tolerance, 1e-3);
  ceres::Solver::Summary summary;
  ceres::Solve(loose, &problem, &summary);
  if (summary.termination_type != ceres::CONVERGENCE || loose.function_tolerance <= options.function_tolerance ||
      gauss_newton_relative_decrease(problem) <= precision)
    return summary;
  ceres::Solver::Options rest = options;
  rest.max_num_iterations = std::max(0, options.max_num_iterations - static_cast<int>(summary.iterations.size()) + 1);
  ceres::Solver::Summary more;
  ceres::Solve(rest, &problem, &more);
  summary.iterations.insert(summary.iterations.end(), more.iterations.begin() + (more.iterations.empty() ? 0 : 1),
                            more.iterations.end());
  summary.final_cost = more.final_cost;
  summary.termination_type = more.termination_type;
  summary.message = more.message;
  return summary;
}

}  // namespace imubridge::estimator
