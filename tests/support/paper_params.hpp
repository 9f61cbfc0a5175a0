#pragma once
// The parameters of the simulator's paper vehicle (sim/scenario.hpp) as PARAMS.json would give them: lever arm
// (r cos beta, 0, -r sin beta), mounting tilt alpha, quadratic drag mu. Tests that estimate a paper flight use them.
#include <cmath>

#include "estimator/params.hpp"
#include "sim/scenario.hpp"

namespace imubridge::test {

inline estimator::ModelParams paper_params() {
  estimator::ModelParams p;
  p.full.lever_arm = {sim::kPaperR * std::cos(sim::kPaperBeta), 0.0, -sim::kPaperR * std::sin(sim::kPaperBeta)};
  p.full.mounting = {0.0, sim::kPaperAlpha, 0.0};
  p.full.drag_quadratic = {sim::kPaperMu, sim::kPaperMu};
  return p;
}

}  // namespace imubridge::test
