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
double gradient_of(const Linear& l, const Eigen::VectorXd& x, int i) { return l.a.col(i).dot(l.a * x - l.b); }

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

// The cost decrease the Gauss-Newton step over the coordinates `free` promises, relative to the cost.
double promise_over(const LinearProblem& p, const std::vector<int>& free) {
  Eigen::MatrixXd a(p.l.a.rows(), static_cast<Eigen::Index>(free.size()));
  for (std::size_t f = 0; f < free.size(); ++f) a.col(static_cast<Eigen::Index>(f)) = p.l.a.col(free[f]);
  const Eigen::VectorXd g = a.transpose() * (p.l.a * p.x - p.l.b);
  return 0.5 * g.dot((a.transpose() * a).ldlt().solve(g)) / cost_at(p.l, p.x);
}

// d cost / d x[i] where the problem stands.
double gradient_at(const LinearProblem& p, int i) { return gradient_of(p.l, p.x, i); }

// x[2] on a bound its gradient presses it against: below 0.5 for a positive gradient, above for a negative one.
void press_against_bound(LinearProblem& p, double bound) {
  if (gradient_at(p, 2) > 0.0) {
    p.problem.SetParameterLowerBound(p.x.data(), 2, bound);
  } else {
    p.problem.SetParameterUpperBound(p.x.data(), 2, bound);
  }
}

TEST(GaussNewtonDecrease, LeavesOutHeldCoordinatesAndThosePressedAgainstABound) {
  LinearProblem p(6);
  const double all = gauss_newton_relative_decrease(p.problem);
  // Only coordinate 0 may move: the promise is that of the 1-D problem in it.
  p.problem.SetManifold(p.x.data(), new ceres::SubsetManifold(3, {1}));
  press_against_bound(p, 0.5);  // x[2] sits on it
  EXPECT_NEAR(gauss_newton_relative_decrease(p.problem), promise_over(p, {0}), 1e-6 * all);
  EXPECT_LT(gauss_newton_relative_decrease(p.problem), all);
}

// On its bound with the gradient pulling it inside, a coordinate is free (its KKT multiplier has the wrong sign).
TEST(GaussNewtonDecrease, CountsACoordinatePulledOffItsBoundAsFree) {
  LinearProblem p(6);
  p.problem.SetManifold(p.x.data(), new ceres::SubsetManifold(3, {1}));
  if (gradient_at(p, 2) > 0.0) {
    p.problem.SetParameterUpperBound(p.x.data(), 2, 0.5);
  } else {
    p.problem.SetParameterLowerBound(p.x.data(), 2, 0.5);
  }
  EXPECT_NEAR(gauss_newton_relative_decrease(p.problem), promise_over(p, {0, 2}), 1e-6 * promise_over(p, {0, 2}));
  EXPECT_GT(gauss_newton_relative_decrease(p.problem), promise_over(p, {0}) * (1.0 + 1e-6));
}

// Two strongly correlated parameters (as the 3-D model's linear and quadratic drag: correlation -0.92) and a third,
// linear in them, with the optimum of x[1] below its lower bound 0 (as the quadratic drag's on EuRoC MH_01). Bounded
// LM computes each step as if x[1] could go negative and cuts it at 0; the cut steps gain a fraction of what they
// promise, and LM creeps along the bound.
struct BoundedProblem {
  BoundedProblem() : l(Linear{Eigen::MatrixXd(400, 3), Eigen::VectorXd(400)}), x(Eigen::Vector3d(0.5, 0.5, 0.5)) {
    std::mt19937 rng(11);
    std::normal_distribution<double> n;
    for (int i = 0; i < l.a.rows(); ++i) {
      const double u = n(rng), v = n(rng);
      l.a.row(i) << u, -0.99 * u + 0.14 * v, n(rng);
      l.b[i] = l.a.row(i).dot(Eigen::Vector3d(1.0, -1.0, 2.0)) + n(rng);
    }
    add(problem, l, x.data());
    problem.SetParameterLowerBound(x.data(), 1, 0.0);
  }
  // The optimum with x[1] on its bound: least squares over the other two.
  Eigen::Vector3d bounded_optimum() const {
    Eigen::MatrixXd a(l.a.rows(), 2);
    a << l.a.col(0), l.a.col(2);
    const Eigen::Vector2d rest = a.colPivHouseholderQr().solve(l.b);
    return {rest[0], 0.0, rest[1]};
  }
  Linear l;
  Eigen::VectorXd x;
  ceres::Problem problem;
};

ceres::Solver::Options tight_options() {
  ceres::Solver::Options options;
  options.function_tolerance = 1e-10;
  options.gradient_tolerance = 1e-14;
  options.parameter_tolerance = 1e-12;
  options.max_num_iterations = 100;
  return options;
}

TEST(SolveToPrecision, HoldsACoordinatePressedAgainstItsBoundAndFinishesOnTheOthers) {
  BoundedProblem plain;
  ceres::Solver::Summary creep;
  ceres::Solve(tight_options(), &plain.problem, &creep);
  ASSERT_GT(creep.iterations.size(), 20u) << "bounded LM alone must creep here: the test would show nothing";

  // Ten "independent residuals" make the loose tolerance 1e-2, above what the cut steps gain: LM stops loosely
  // after a few of them, as on the real flight (where they gain 1e-6 of the cost against a tolerance of 5e-6).
  BoundedProblem p;
  const ceres::Solver::Summary summary = solve_to_precision(p.problem, tight_options(), 10.0);
  const Eigen::Vector3d optimum = p.bounded_optimum();
  // Standard errors of the two free parameters (unit noise), and the bound's KKT multiplier: d cost / d x[1] >= 0.
  Eigen::MatrixXd a(p.l.a.rows(), 2);
  a << p.l.a.col(0), p.l.a.col(2);
  const Eigen::Vector2d std_error = (a.transpose() * a).inverse().diagonal().cwiseSqrt();
  EXPECT_EQ(p.x[1], 0.0);
  EXPECT_LT(std::abs(p.x[0] - optimum[0]), kPrecisionInStandardErrors * std_error[0]);
  EXPECT_LT(std::abs(p.x[2] - optimum[2]), kPrecisionInStandardErrors * std_error[1]);
  EXPECT_GT(gradient_of(p.l, p.x, 1), 0.0);
  EXPECT_LE(summary.iterations.size(), 10u) << "iterations " << summary.iterations.size() - 1;
  EXPECT_EQ(summary.termination_type, ceres::CONVERGENCE);
}

// 2-D vectors f turned by an angle to match a model c u, with residuals large against what the model explains (as
// the horizontal specific force against the drag on a real flight, turned by the mounting's yaw): the cost's
// curvature in the angle is c^2 sum |u|^2, J^T J's sum |f|^2, about 100 times more here. Gauss-Newton steps in the
// angle reach 1/100 of the way each, gaining twice what they promise, and their promise is 100 times too small.
struct Turned {
  template <typename T>
  bool operator()(const T* p, T* r) const {
    const T c = cos(p[0]), s = sin(p[0]);
    for (std::size_t i = 0; i < f.size(); ++i) {
      r[2 * i] = c * f[i].x() - s * f[i].y() - p[1] * u[i].x();
      r[2 * i + 1] = s * f[i].x() + c * f[i].y() - p[1] * u[i].y();
    }
    return true;
  }
  std::vector<Eigen::Vector2d> f, u;
};

struct TurnedProblem {
  static constexpr int kSamples = 200;
  TurnedProblem() {
    std::mt19937 rng(3);
    std::normal_distribution<double> n;
    for (int i = 0; i < kSamples; ++i) {
      const Eigen::Vector2d u(n(rng), n(rng));
      turned.u.push_back(u);
      turned.f.push_back(Eigen::Rotation2Dd(-0.3) * u + 10.0 * Eigen::Vector2d(n(rng), n(rng)));
    }
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<Turned, 2 * kSamples, 2>(new Turned(turned)), nullptr, p);
  }
  // The optimum in closed form: for a given angle c is linear; the angle maximises sum u . R f = A cos + B sin.
  double optimal_cost() const {
    double a = 0.0, b = 0.0, uu = 0.0, ff = 0.0;
    for (std::size_t i = 0; i < turned.f.size(); ++i) {
      const Eigen::Vector2d& f = turned.f[i];
      const Eigen::Vector2d& u = turned.u[i];
      a += u.dot(f);
      b += u.y() * f.x() - u.x() * f.y();
      uu += u.squaredNorm();
      ff += f.squaredNorm();
    }
    return 0.5 * (ff - (a * a + b * b) / uu);
  }
  double cost() {
    double c = 0.0;
    problem.Evaluate(ceres::Problem::EvaluateOptions(), &c, nullptr, nullptr, nullptr);
    return c;
  }
  Turned turned;
  double p[2] = {0.0, 0.5};
  ceres::Problem problem;
};

TEST(SolveToPrecision, SettlesWhereGaussNewtonMisjudgesTheCurvature) {
  const double independent_residuals = 2.0 * TurnedProblem::kSamples;
  const double precision = kPrecisionInStandardErrors * kPrecisionInStandardErrors / independent_residuals;
  {
    // LM stopped loosely here is further from the optimum than the precision, though its Gauss-Newton check says
    // it is not: the check alone would stop.
    TurnedProblem loose;
    ceres::Solver::Options options = tight_options();
    options.function_tolerance = precision;
    ceres::Solver::Summary summary;
    ceres::Solve(options, &loose.problem, &summary);
    ASSERT_LE(gauss_newton_relative_decrease(loose.problem), precision);
    ASSERT_GT(loose.cost() - loose.optimal_cost(), 3.0 * precision * loose.cost())
        << "the loose stop must be far here: the test would show nothing";
  }
  TurnedProblem p;
  const ceres::Solver::Summary summary = solve_to_precision(p.problem, tight_options(), independent_residuals);
  // Within k standard errors: the cost above the optimum at most k^2 / n of it.
  EXPECT_LE(p.cost() - p.optimal_cost(), precision * p.cost());
  EXPECT_LE(summary.iterations.size(), 20u) << "iterations " << summary.iterations.size() - 1;
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
