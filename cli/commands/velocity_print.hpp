#pragma once
// How identify and diagnose print what a model does for the velocity: one line, horizontal then per axis.
#include <cstdio>

#include "identification/velocity_scores.hpp"

namespace imubridge::cli {

inline void print_velocity_scores(const estimator::VelocityScores& v, const char* indent = "  ") {
  std::printf("%svelocity RMSE train %.3f (x %.3f, y %.3f), validation %.3f (x %.3f, y %.3f) m/s%s%s\n", indent,
              v.train.horizontal, v.train.axis.x(), v.train.axis.y(), v.validation.horizontal, v.validation.axis.x(),
              v.validation.axis.y(), v.note.empty() ? "" : ": ", v.note.c_str());
}

}  // namespace imubridge::cli
