// The bounded real-coded GA on objectives whose minimum is known in closed form.
#include "identification/ga.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

namespace imubridge::estimator {
namespace {

// A 4-D bowl with unequal curvatures, centred at (0.3, -1.2, 2.5, 0.01): minimum 0 there.
double bowl(std::span<const double> x) {
  const double c[4] = {0.3, -1.2, 2.5, 0.01};
  const double w[4] = {1.0, 10.0, 0.1, 100.0};
  double sum = 0.0;
  for (int i = 0; i < 4; ++i) sum += w[i] * (x[i] - c[i]) * (x[i] - c[i]);
  return sum;
}

const GaBounds kBowlBounds{{-1.0, -3.0, 0.0, 0.0}, {1.0, 3.0, 5.0, 0.1}};

TEST(Ga, FindsTheMinimumOfABowl) {
  const GaResult r = minimize_ga(bowl, kBowlBounds, {});
  EXPECT_NEAR(r.best[0], 0.3, 1e-3);
  EXPECT_NEAR(r.best[1], -1.2, 1e-3);
  EXPECT_NEAR(r.best[2], 2.5, 1e-2);
  EXPECT_NEAR(r.best[3], 0.01, 1e-4);
  EXPECT_LT(r.best_objective, 1e-5);
  EXPECT_EQ(r.best_objective, bowl(r.best));
}

TEST(Ga, StaysInsideTheBoxAndFindsAMinimumOnItsEdge) {
  // The bowl's centre lies outside this box in genes 0 and 3: the constrained minimum is on the bounds.
  const GaBounds box{{0.5, -3.0, 0.0, 0.05}, {1.0, 3.0, 5.0, 0.1}};
  bool inside = true;
  const auto watched = [&](std::span<const double> x) {
    for (std::size_t i = 0; i < x.size(); ++i) inside = inside && x[i] >= box.lower[i] && x[i] <= box.upper[i];
    return bowl(x);
  };
  const GaResult r = minimize_ga(watched, box, {});
  EXPECT_TRUE(inside);
  EXPECT_NEAR(r.best[0], 0.5, 1e-4);
  EXPECT_NEAR(r.best[3], 0.05, 1e-5);
  EXPECT_NEAR(r.best[1], -1.2, 1e-3);
}

TEST(Ga, ConvergenceCurveIsTheBestSoFarPerGeneration) {
  GaOptions o;
  o.population = 30;
  o.generations = 40;
  o.elite = 3;
  const GaResult r = minimize_ga(bowl, kBowlBounds, o);
  ASSERT_EQ(r.convergence.size(), 41u);  // the initial generation, then one entry per generation
  for (std::size_t g = 1; g < r.convergence.size(); ++g) EXPECT_LE(r.convergence[g], r.convergence[g - 1]);
  EXPECT_EQ(r.convergence.back(), r.best_objective);
  EXPECT_LT(r.convergence.back(), r.convergence.front());
  // Elites are carried over without being evaluated again.
  EXPECT_EQ(r.evaluations, 30u + 40u * (30u - 3u));
}

TEST(Ga, SameSeedGivesBitIdenticalResults) {
  GaOptions o;
  o.generations = 50;
  o.seed = 42;
  const GaResult a = minimize_ga(bowl, kBowlBounds, o);
  const GaResult b = minimize_ga(bowl, kBowlBounds, o);
  EXPECT_EQ(a.best, b.best);  // exact equality of doubles: bit for bit
  EXPECT_EQ(a.convergence, b.convergence);
  o.seed = 43;
  const GaResult c = minimize_ga(bowl, kBowlBounds, o);
  EXPECT_NE(a.convergence, c.convergence);
}

TEST(Ga, NonFiniteValuesRankLast) {
  // Undefined (NaN) on half of the box, infinite on a band: the minimum in the defined part is still found.
  const auto partial = [](std::span<const double> x) {
    if (x[0] < 0.0) return std::numeric_limits<double>::quiet_NaN();
    if (x[0] > 0.9) return std::numeric_limits<double>::infinity();
    return (x[0] - 0.4) * (x[0] - 0.4) + (x[1] + 0.2) * (x[1] + 0.2);
  };
  const GaResult r = minimize_ga(partial, {{-1.0, -1.0}, {1.0, 1.0}}, {});
  EXPECT_NEAR(r.best[0], 0.4, 1e-3);
  EXPECT_NEAR(r.best[1], -0.2, 1e-3);
}

TEST(Ga, RejectsBadBoundsAndOptions) {
  const auto square = [](std::span<const double> x) { return x[0] * x[0]; };
  EXPECT_THROW(minimize_ga(square, {{}, {}}, {}), std::invalid_argument);
  EXPECT_THROW(minimize_ga(square, {{0.0}, {0.0}}, {}), std::invalid_argument);
  EXPECT_THROW(minimize_ga(square, {{0.0, 0.0}, {1.0}}, {}), std::invalid_argument);
  EXPECT_THROW(minimize_ga(square, {{0.0}, {std::numeric_limits<double>::infinity()}}, {}), std::invalid_argument);
  const auto with = [](auto change) {
    GaOptions o;
    change(o);
    return o;
  };
  const GaBounds ok{{0.0}, {1.0}};
  EXPECT_THROW(minimize_ga(square, ok, with([](GaOptions& o) { o.population = 3; })), std::invalid_argument);
  EXPECT_THROW(minimize_ga(square, ok, with([](GaOptions& o) { o.generations = -1; })), std::invalid_argument);
  EXPECT_THROW(minimize_ga(square, ok, with([](GaOptions& o) { o.mutation = 1.5; })), std::invalid_argument);
  EXPECT_THROW(minimize_ga(square, ok, with([](GaOptions& o) { o.crossover = -0.1; })), std::invalid_argument);
  EXPECT_THROW(minimize_ga(square, ok, with([](GaOptions& o) { o.tournament = 0; })), std::invalid_argument);
}

}  // namespace
}  // namespace imubridge::estimator
