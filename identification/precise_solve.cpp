#include "identification/precise_solve.hpp"

#include <ceres/crs_matrix.h>
#include <ceres/manifold.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <vector>

namespace imubridge::estimator {
namespace {

bool on_bound(double value, double bound) {
  return std::isfinite(bound) && std::abs(bound) < std::numeric_limits<double>::max() &&
         std::abs(value - bound) <= 1e-12 * std::max(1.0, std::abs(bound));
}

// Which ambient coordinate each tangent column of `block` moves, when its manifold only selects coordinates (none
// does; SubsetManifold does); empty for any other manifold, whose coordinates can be neither judged nor held alone.
std::vector<int> selected_coordinates(const ceres::Problem& problem, double* block) {
  const int size = problem.ParameterBlockSize(block), tangent = problem.ParameterBlockTangentSize(block);
  std::vector<int> coordinate(static_cast<std::size_t>(tangent));
  const ceres::Manifold* manifold = problem.GetManifold(block);
  if (manifold == nullptr) {
    for (int j = 0; j < tangent; ++j) coordinate[static_cast<std::size_t>(j)] = j;
    return coordinate;
  }
  std::vector<double> plus(static_cast<std::size_t>(size * tangent));
  manifold->PlusJacobian(block, plus.data());
  for (int j = 0; j < tangent; ++j) {
    int nonzero = 0;
    for (int i = 0; i < size; ++i) {
      const double d = plus[static_cast<std::size_t>(i * tangent + j)];
      if (d == 0.0) continue;
      if (d != 1.0 || ++nonzero > 1) return {};
      coordinate[static_cast<std::size_t>(j)] = i;
    }
    if (nonzero == 0) return {};
  }
  return coordinate;
}

// One column of the Jacobian: the block it belongs to, the ambient coordinate it moves (-1: not one alone), and
// whether the solver may move it at all (not in a constant block).
struct Column {
  double* block;
  int coordinate;
  bool variable;
};

// The problem's value, gradient and Jacobian where it stands, with what each column is.
struct Linearization {
  double cost = 0.0;
  std::vector<double> gradient;
  ceres::CRSMatrix jacobian;
  std::vector<Column> columns;
};

bool linearize(ceres::Problem& problem, Linearization& out) {
  std::vector<double*> blocks;
  problem.GetParameterBlocks(&blocks);
  ceres::Problem::EvaluateOptions evaluate;
  evaluate.parameter_blocks = blocks;
  if (!problem.Evaluate(evaluate, &out.cost, nullptr, &out.gradient, &out.jacobian)) return false;
  for (double* block : blocks) {
    const int tangent = problem.ParameterBlockTangentSize(block);
    const bool variable = !problem.IsParameterBlockConstant(block);
    const std::vector<int> coordinate = selected_coordinates(problem, block);
    for (int j = 0; j < tangent; ++j)
      out.columns.push_back({block, coordinate.empty() ? -1 : coordinate[static_cast<std::size_t>(j)], variable});
  }
  return true;
}

// Whether a column sits on a bound that the cost's gradient presses it against: the bound is active with a KKT
// multiplier of the right sign, so no step may move it, and the optimum over the others is the optimum. On a bound
// with the gradient pulling inward, it is as free as any other.
bool pressed_against_bound(const ceres::Problem& problem, const Column& c, double gradient) {
  if (!c.variable || c.coordinate < 0) return false;
  const double x = c.block[c.coordinate];
  return (gradient >= 0.0 && on_bound(x, problem.GetParameterLowerBound(c.block, c.coordinate))) ||
         (gradient <= 0.0 && on_bound(x, problem.GetParameterUpperBound(c.block, c.coordinate)));
}

// Runs LM on from where the problem stands, with what is left of `budget`'s iterations, into one summary.
void solve_on(ceres::Problem& problem, const ceres::Solver::Options& options, int budget,
              ceres::Solver::Summary& summary) {
  ceres::Solver::Options rest = options;
  rest.max_num_iterations = std::max(0, budget - static_cast<int>(summary.iterations.size()) + 1);
  ceres::Solver::Summary more;
  ceres::Solve(rest, &problem, &more);
  summary.iterations.insert(summary.iterations.end(), more.iterations.begin() + (more.iterations.empty() ? 0 : 1),
                            more.iterations.end());
  summary.final_cost = more.final_cost;
  summary.termination_type = more.termination_type;
  summary.message = more.message;
}

// The Gauss-Newton model over the columns that may move (neither held nor pressed against a bound): J^T J and the
// gradient there.
struct GaussNewtonModel {
  Linearization at;
  std::vector<int> free;  // columns
  Eigen::MatrixXd h;
  Eigen::VectorXd g;
};

bool gauss_newton_model(ceres::Problem& problem, GaussNewtonModel& out) {
  if (!linearize(problem, out.at) || !(out.at.cost > 0.0)) return false;
  for (std::size_t k = 0; k < out.at.columns.size(); ++k) {
    if (out.at.columns[k].variable && !pressed_against_bound(problem, out.at.columns[k], out.at.gradient[k]))
      out.free.push_back(static_cast<int>(k));
  }
  if (out.free.empty()) return false;
  const ceres::CRSMatrix& jacobian = out.at.jacobian;
  Eigen::MatrixXd j = Eigen::MatrixXd::Zero(jacobian.num_rows, static_cast<Eigen::Index>(out.free.size()));
  std::vector<int> position(static_cast<std::size_t>(jacobian.num_cols), -1);
  for (std::size_t f = 0; f < out.free.size(); ++f)
    position[static_cast<std::size_t>(out.free[f])] = static_cast<int>(f);
  for (int r = 0; r < jacobian.num_rows; ++r) {
    for (int k = jacobian.rows[static_cast<std::size_t>(r)]; k < jacobian.rows[static_cast<std::size_t>(r) + 1]; ++k) {
      const int p = position[static_cast<std::size_t>(jacobian.cols[static_cast<std::size_t>(k)])];
      if (p >= 0) j(r, p) = jacobian.values[static_cast<std::size_t>(k)];
    }
  }
  out.g.resize(static_cast<Eigen::Index>(out.free.size()));
  for (std::size_t f = 0; f < out.free.size(); ++f)
    out.g[static_cast<Eigen::Index>(f)] = out.at.gradient[static_cast<std::size_t>(out.free[f])];
  out.h = j.transpose() * j;
  return true;
}

// The step the model `b` (J^T J, or it corrected) takes, minimum-norm where it is singular.
Eigen::VectorXd model_step(const Eigen::MatrixXd& b, const Eigen::VectorXd& g) {
  return -b.completeOrthogonalDecomposition().solve(g);
}

// Every parameter block's values, to go back to.
class Values {
 public:
  explicit Values(const ceres::Problem& problem) {
    problem.GetParameterBlocks(&blocks_);
    for (double* block : blocks_) saved_.emplace_back(block, block + problem.ParameterBlockSize(block));
  }
  void restore() const {
    for (std::size_t b = 0; b < blocks_.size(); ++b) std::copy(saved_[b].begin(), saved_[b].end(), blocks_[b]);
  }

 private:
  std::vector<double*> blocks_;
  std::vector<std::vector<double>> saved_;
};

double cost_of(ceres::Problem& problem) {
  double cost = 0.0;
  if (!problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr, nullptr))
    return std::numeric_limits<double>::infinity();
  return cost;
}

bool gradient_over(ceres::Problem& problem, const std::vector<int>& free, double& cost, Eigen::VectorXd& g) {
  std::vector<double*> blocks;
  problem.GetParameterBlocks(&blocks);
  ceres::Problem::EvaluateOptions evaluate;
  evaluate.parameter_blocks = blocks;
  std::vector<double> gradient;
  if (!problem.Evaluate(evaluate, &cost, nullptr, &gradient, nullptr)) return false;
  g.resize(static_cast<Eigen::Index>(free.size()));
  for (std::size_t f = 0; f < free.size(); ++f)
    g[static_cast<Eigen::Index>(f)] = gradient[static_cast<std::size_t>(free[f])];
  return true;
}

// Puts the problem at `from` plus `scale` times `step` over the model's free columns (through each block's
// manifold), kept within the bounds.
void move_along(ceres::Problem& problem, const Values& from, const GaussNewtonModel& m, const Eigen::VectorXd& step,
                double scale) {
  from.restore();
  std::map<double*, std::vector<double>> delta;  // tangent steps by block
  std::map<double*, int> first_column;
  for (std::size_t k = 0; k < m.at.columns.size(); ++k) {
    double* block = m.at.columns[k].block;
    first_column.try_emplace(block, static_cast<int>(k));
    delta.try_emplace(block, static_cast<std::size_t>(problem.ParameterBlockTangentSize(block)), 0.0);
  }
  for (std::size_t f = 0; f < m.free.size(); ++f) {
    double* block = m.at.columns[static_cast<std::size_t>(m.free[f])].block;
    delta[block][static_cast<std::size_t>(m.free[f] - first_column[block])] =
        scale * step[static_cast<Eigen::Index>(f)];
  }
  for (auto& [block, d] : delta) {
    const int size = problem.ParameterBlockSize(block);
    std::vector<double> moved(block, block + size);
    if (const ceres::Manifold* manifold = problem.GetManifold(block)) {
      manifold->Plus(block, d.data(), moved.data());
    } else {
      for (int i = 0; i < size; ++i) moved[static_cast<std::size_t>(i)] += d[static_cast<std::size_t>(i)];
    }
    for (int i = 0; i < size; ++i) {
      moved[static_cast<std::size_t>(i)] =
          std::clamp(moved[static_cast<std::size_t>(i)], problem.GetParameterLowerBound(block, i),
                     problem.GetParameterUpperBound(block, i));
    }
    std::copy(moved.begin(), moved.end(), block);
  }
}

// How far along `step` to go, the problem left there: the step if it gains; where it gains more than it promised
// (ratio rho > 1, the cost's curvature along it below the model's), the minimum of the parabola through that gain,
// 1/(2 - rho) steps, if better still; halved until it gains otherwise. 0: nothing gained, the problem where it was.
double line_search(ceres::Problem& problem, const Values& from, const GaussNewtonModel& m, const Eigen::VectorXd& step,
                   double cost, double promise) {
  constexpr double kMaxExtension = 1e3;
  move_along(problem, from, m, step, 1.0);
  const double at_step = cost_of(problem);
  if (at_step < cost) {
    const double ratio = (cost - at_step) / promise;
    if (ratio > 1.0) {
      const double extended = 1.0 / std::max(2.0 - ratio, 1.0 / kMaxExtension);
      move_along(problem, from, m, step, extended);
      if (cost_of(problem) < at_step) return extended;
      move_along(problem, from, m, step, 1.0);
    }
    return 1.0;
  }
  for (double scale = 0.5; scale > 1e-3; scale *= 0.5) {
    move_along(problem, from, m, step, scale);
    if (cost_of(problem) < cost) return scale;
  }
  from.restore();
  return 0.0;
}

// The step's promise corrected by the cost at the step: where it gains more than it promised (ratio rho > 1), the
// cost's curvature along it is below the model's, and the parabola through that gain puts the minimum along the step
// at 1/(2 - rho) steps, worth promise/(2 - rho). The problem is left where it was.
double curvature_corrected_promise(ceres::Problem& problem, const Values& from, const GaussNewtonModel& m,
                                   const Eigen::VectorXd& step, double cost, double promise) {
  move_along(problem, from, m, step, 1.0);
  const double ratio = (cost - cost_of(problem)) / promise;
  from.restore();
  return ratio > 1.0 ? promise / std::max(2.0 - ratio, 1e-3) : promise;
}

// Takes the problem to within `precision` of the optimum over the columns that may move where it stands, by
// quasi-Newton steps: J^T J corrected by BFGS updates from the gradients along the steps. J^T J alone misjudges the
// cost's curvature where the residuals are large against what the parameters explain: the second-order term
// sum r d2r cancels much of it (on the real flight, the mounting's yaw, which turns the horizontal specific force in
// its plane: LM's steps gained 1.99 times their promise, reached 1/100 of the way each, and crept for 100
// iterations, while their promise told the check it was done). Returns the steps taken (0: it was there), -1 if it
// did not get there.
int settle(ceres::Problem& problem, double precision, ceres::Solver::Summary& summary) {
  constexpr int kMaxSteps = 12;
  GaussNewtonModel m;
  if (!gauss_newton_model(problem, m)) return 0;
  Eigen::MatrixXd b = m.h;
  Eigen::VectorXd g = m.g;
  double cost = m.at.cost;
  for (int k = 0;; ++k) {
    const Eigen::VectorXd step = model_step(b, g);
    const double promise = -0.5 * g.dot(step);
    const Values from(problem);
    if (!(promise > precision * cost) &&
        !(curvature_corrected_promise(problem, from, m, step, cost, promise) > precision * cost))
      return k;
    if (k == kMaxSteps) return -1;
    const double scale = line_search(problem, from, m, step, cost, promise);
    Eigen::VectorXd moved_gradient;
    double moved_cost = 0.0;
    if (scale == 0.0 || !gradient_over(problem, m.free, moved_cost, moved_gradient)) return -1;
    const Eigen::VectorXd s = scale * step, y = moved_gradient - g, bs = b * s;
    if (y.dot(s) > 0.0 && s.dot(bs) > 0.0) b += y * y.transpose() / y.dot(s) - bs * bs.transpose() / s.dot(bs);
    ceres::IterationSummary iteration;
    iteration.iteration = static_cast<int>(summary.iterations.size());
    iteration.cost = moved_cost;
    iteration.cost_change = cost - moved_cost;
    iteration.step_is_successful = true;
    summary.iterations.push_back(iteration);
    summary.final_cost = moved_cost;
    g = moved_gradient;
    cost = moved_cost;
  }
}

// From LM's loose stop on to the precise one. The coordinates pressed against their bounds (the gradient pushing
// them out: their KKT multipliers have the right sign) are held where they are, and the others settled by
// quasi-Newton steps, which are then not cut at a bound, each gaining a fraction of what it promised, as LM's were;
// then the check again with the pressed ones found anew: one the gradient now pulls back inside is free, and
// settled with the others. LM goes on to `tight`'s own tolerance only if that does not end.
void finish_to_precision(ceres::Problem& problem, const ceres::Solver::Options& tight, double precision,
                         ceres::Solver::Summary& summary) {
  constexpr int kRounds = 4;
  for (int round = 0; round < kRounds; ++round) {
    const int steps = settle(problem, precision, summary);
    if (steps == 0) return;
    if (steps < 0) break;
  }
  solve_on(problem, tight, tight.max_num_iterations, summary);
}

}  // namespace

double gauss_newton_relative_decrease(ceres::Problem& problem) {
  GaussNewtonModel m;
  if (!gauss_newton_model(problem, m)) return 0.0;
  return -0.5 * m.g.dot(model_step(m.h, m.g)) / m.at.cost;
}

ceres::Solver::Summary solve_to_precision(ceres::Problem& problem, const ceres::Solver::Options& options,
                                          double independent_residuals) {
  const double precision =
      kPrecisionInStandardErrors * kPrecisionInStandardErrors / std::max(independent_residuals, 1.0);
  ceres::Solver::Options loose = options;
  loose.function_tolerance = std::clamp(precision, options.function_tolerance, 1e-3);
  ceres::Solver::Summary summary;
  ceres::Solve(loose, &problem, &summary);
  if (summary.termination_type != ceres::CONVERGENCE || loose.function_tolerance <= options.function_tolerance)
    return summary;
  finish_to_precision(problem, options, precision, summary);
  return summary;
}

}  // namespace imubridge::estimator
