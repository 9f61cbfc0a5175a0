#pragma once
// Levenberg-Marquardt fits of the accelerometer models with Ceres (autodiff through identification/cost_functors.hpp), and
// the uncertainty of a solution: standard errors and correlations from ceres::Covariance, scaled by the residual
// variance. Single-threaded and deterministic.
#include <Eigen/Core>
#include <array>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "estimator/full_model.hpp"
#include "estimator/paper_model.hpp"
#include "identification/cost_functors.hpp"

namespace imubridge::estimator {

// The covariance (J^T J)^-1 of the free parameters at a solution, times s^2 = sum(residual^2) / (residuals - free
// parameters): the linearised standard errors under white residuals. A correlation near +-1 names two parameters
// the data cannot tell apart.
struct Uncertainty {
  std::vector<std::string> names;  // the free parameters in matrix order: "r", "beta", ..., "lever_arm.0", ...
  Eigen::VectorXd value;           // their values at the solution, in their units (m, rad, 1/m, ...)
  Eigen::VectorXd std_error;       // same units
  Eigen::MatrixXd correlation;
  std::string failure;  // why ceres::Covariance failed (rank-deficient Jacobian); std_error and correlation are empty
};

struct SolverReport {
  int iterations = 0;
  bool converged = false;
  double initial_objective = 0.0;  // sqrt(sum of squared residuals), eq. (15)'s OF
  double final_objective = 0.0;
  std::string message;  // Ceres' reason for stopping
};

// ---- The paper's model, one axis: parameters (r, beta, alpha, mu) ----

// The closed-form least-squares fit. Eq. (14) is linear in (g sin(alpha), r cos(beta) cos(alpha),
// r sin(beta) cos(alpha), mu); their linear fit, mapped back, is the unconstrained optimum of OF. mu is clamped to 0
// if the data fit a negative one. Throws std::invalid_argument for fewer than 4 samples or singular data.
PaperAxisParams paper_linear_fit(std::span<const PaperSample> samples);

struct PaperFit {
  PaperAxisParams params;
  SolverReport report;
};
// LM from `initial`, with r >= 0 and mu >= 0. Throws std::invalid_argument for no samples.
PaperFit fit_paper_lm(std::span<const PaperSample> samples, const PaperAxisParams& initial);
Uncertainty paper_uncertainty(std::span<const PaperSample> samples, const PaperAxisParams& params);

// ---- The 3-D model: FullModelParams' five blocks ----

enum class FullBlock { lever_arm, mounting, drag_linear, drag_quadratic, accel_bias };
inline constexpr int kFullBlocks = 5;
inline constexpr std::array<int, kFullBlocks> kFullBlockSizes{3, 3, 2, 2, 3};
// As in PARAMS.json.
inline constexpr std::array<std::string_view, kFullBlocks> kFullBlockNames{"lever_arm", "mounting", "drag_linear",
                                                                           "drag_quadratic", "accel_bias"};
// The blocks' storage inside `p`, in FullBlock order: what the solver and the GA write into.
std::array<double*, kFullBlocks> parameter_blocks(FullModelParams& p);

// Which blocks stay at their initial value. The bias's z component always does: with the thrust taken from the
// body-z reading (FullResidual) it only shifts T and nothing in the data determines it.
struct FullHold {
  std::array<bool, kFullBlocks> blocks{};
  bool held(FullBlock b) const { return blocks[static_cast<int>(b)]; }
};

struct FullFit {
  FullModelParams params;
  SolverReport report;
};
// LM from `initial`, with the drag coefficients >= 0. Throws std::invalid_argument for no samples or every block
// held.
FullFit fit_full_lm(std::span<const FullSample> samples, const FullModelParams& initial, const FullHold& hold = {});
Uncertainty full_uncertainty(std::span<const FullSample> samples, const FullModelParams& params,
                             const FullHold& hold = {});
// sqrt(sum over samples and horizontal axes of FullResidual^2): eq. (15)'s OF for the 3-D model.
double full_objective(const FullModelParams& params, std::span<const FullSample> samples);
// Per horizontal body axis: sqrt(mean FullResidual^2); 0 for no samples.
Eigen::Vector2d full_rmse(const FullModelParams& params, std::span<const FullSample> samples);

}  // namespace imubridge::estimator
