#include "identification/precise_solve.hpp"

#include <ceres/ceres.h>
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <random>

namespace imubridge::estimator {
namespace {

// r = A x - b: linear, so the Gauss-Newton step lands on the optimum and its promise is exactly the cost it saves.
struct Linear {
  Eigen::MatrixXd a;
  Eigen::VectorXd b;
  bool operator()(double const* const* x, double* r) const {
    const Eigen::Map<const Eigen::VectorXd> v(x[0], a.cols());
    Eigen::Map<Eigen::VectorXd>(r, a.rows()) = a * v - b;
    return true;
  }
};

Linear random_linear(int rows, int cols, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n;
  Linear l{Eigen::MatrixXd(rows, cols), Eigen::VectorXd(rows)};
  for (int i = 0; i < rows; ++i) {
    for (int j = 0; j < cols; ++j) l.a(i, j) = n(rng);
    l.b[i] = n(rng);
  }
  return l;
}

void add(ceres::Problem& problem, const Linear& l, double* x) {
  auto* cost = new ceres::DynamicNumericDiffCostFunction<Linear>(new Linear(l));
  cost->AddParameterBlock(static_cast<int>(l.a.cols()));
  cost->SetNumResiduals(static_cast<int>(l.a.rows()));
  problem.AddResidualBlock(cost, nullptr, x);
}

double cost_at(const Linear& l, const Eigen::VectorXd& x) { return 0.5 * (l.a * x - l.b).squaredNorm(); }

// 40 random residuals in 3 parameters, started away from their optimum.
struct LinearProblem {
  explicit LinearProblem(unsigned seed) : l(random_linear(40, 3, seed)), x(Eigen::Vector3d(1.0, -2.0, 0.5)) {
    add(problem, l, x.data());
  }
  Linear l;
  Eigen::VectorXd x;
  ceres::Problem problem;
};

TEST(GaussNewtonDecrease, IsTheCostTheStepSavesOnALinearProblem) {
  LinearProblem p(5);
  const Eigen::VectorXd optimum = p.l.a.colPivHouseholderQr().solve(p.l.b);
  const double expected = (cost_at(p.l, p.x) - cost_at(p.l, optimum)) / cost_at(p.l, p.x);
  EXPECT_NEAR(gauss_newton_relative_decrease(p.problem), expected, 1e-6 * expected);
  p.x = optimum;
  EXPECT_LT(gauss_newton_relative_decrease(p.problem), 1e-12);
}

TEST(GaussNewtonDecrease, LeavesOutHeldCoordinatesAndThoseOnABound) {
  LinearProblem p(6);
  const double all = gauss_newton_relative_decrease(p.problem);
  // Only coordinate 0 may move: the promise is that of the 1-D problem in it.
  p.problem.SetManifold(p.x.data(), new ceres::SubsetManifold(3, {1}));
  p.problem.SetParameterLowerBound(p.x.data(), 2, 0.5);  // x[2] sits on it
  const Eigen::VectorXd column = p.l.a.col(0);
  const Eigen::VectorXd rest = p.l.a * p.x - p.l.b;
  const double g = column.dot(rest), h = column.squaredNorm();
  EXPECT_NEAR(gauss_newton_relative_decrease(p.problem), 0.5 * g * g / h / cost_at(p.l, p.x), 1e-6 * all);
  EXPECT_LT(gauss_newton_relative_decrease(p.problem), all);
}

// Rosenbrock's valley as least squares, plus a residual nothing explains (as noise is): LM crawls along the valley
// with steps that each gain little of the cost, so a loose relative-cost stop alone ends far from the optimum; the
// Gauss-Newton check sends it on.
struct Valley {
  template <typename T>
  bool operator()(const T* x, T* r) const {
    r[0] = T(100.0) * (x[1] - x[0] * x[0]);
    r[1] = T(1.0) - x[0];
    r[2] = T(3.0);
    return true;
  }
};

TEST(SolveToPrecision, DoesNotStopWhileTheOptimumIsFar) {
  const auto solve = [](bool precise, double independent_residuals) {
    double x[2] = {-1.2, 1.0};
    ceres::Problem problem;
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<Valley, 3, 2>(new Valley), nullptr, x);
    ceres::Solver::Options options;
    options.function_tolerance = 1e-12;
    options.gradient_tolerance = 1e-14;
    options.parameter_tolerance = 1e-12;
    options.max_num_iterations = 200;
    ceres::Solver::Summary summary;
    if (precise) {
      summary = solve_to_precision(problem, options, independent_residuals);
    } else {
      options.function_tolerance = kPrecisionInStandardErrors * kPrecisionInStandardErrors / independent_residuals;
      ceres::Solve(options, &problem, &summary);
    }
    return Eigen::Vector2d(x[0], x[1]);
  };
  // Ten "independent residuals" make the loose tolerance 1e-2: alone, it stops on the valley's floor.
  const Eigen::Vector2d loose = solve(false, 10.0), precise = solve(true, 10.0);
  EXPECT_GT((loose - Eigen::Vector2d(1.0, 1.0)).norm(), 1e-2)
      << "the loose stop alone must stop early here: " << loose.transpose();
  EXPECT_LT((precise - Eigen::Vector2d(1.0, 1.0)).norm(), 1e-3);
}

}  // namespace
}  // namespace imubridge::estimator
