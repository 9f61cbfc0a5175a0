#pragma once
// Levenberg-Marquardt that stops once the parameters are within a fraction of a standard error of the optimum, for
// fits that report parameters (identify). A relative cost change per iteration decides too early or too late: LM
// crawling along a valley with damped steps gains little per iteration while still far away, and chasing 1e-7 of
// the cost took identify 20 to 40 iterations on a real flight for nothing the standard errors could tell.
#include <ceres/problem.h>
#include <ceres/solver.h>

namespace imubridge::estimator {

// How close: the Gauss-Newton step still left would move the parameters by less than this many standard errors.
inline constexpr double kPrecisionInStandardErrors = 1.0 / 3.0;

// The cost decrease the Gauss-Newton step from the current values promises, relative to the cost: over the
// parameters that are neither held (constant blocks, a SubsetManifold's fixed coordinates) nor on a bound that the
// gradient presses them against (one it pulls back inside counts as free), with a minimum-norm step where the
// Jacobian is rank-deficient. Moving k standard errors from the optimum costs k^2 / n of
// the cost for n independent residuals, so this is (distance in standard errors)^2 / n.
double gauss_newton_relative_decrease(ceres::Problem& problem);

// Solves with `options` but for its stopping rule: LM stops at a relative cost change of k^2 / n (k =
// kPrecisionInStandardErrors, n = `independent_residuals`), and the decrease left there is checked: the Gauss-Newton
// step's promise, corrected by the cost at the step where it gains more than it promised (large residuals). If it is
// worth more than k^2 / n, the parameters the gradient presses against their bounds are held there and the others
// settled by quasi-Newton steps (J^T J corrected by BFGS updates); LM goes on to `options`' own function_tolerance
// only if they do not settle. One summary for all of it, a quasi-Newton step an iteration.
ceres::Solver::Summary solve_to_precision(ceres::Problem& problem, const ceres::Solver::Options& options,
                                          double independent_residuals);

}  // namespace imubridge::estimator
