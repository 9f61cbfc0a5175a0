#pragma once
// A bounded real-coded genetic algorithm, the optimiser of the paper's section VI: tournament selection, simulated
// binary crossover (SBX), polynomial mutation and elitism, all kept inside the box (Deb & Agrawal 1995, Deb 2001).
// Deterministic: every random draw comes from one std::mt19937_64 seeded with `seed`, converted by our own code
// (std::*_distribution are not specified bit for bit), and the objective is called in a fixed order. The same
// seed, options and objective give a bit-identical result.
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

namespace imubridge::estimator {

struct GaOptions {
  int population = 60;          // individuals per generation
  int generations = 300;        // generations after the random initial one
  double mutation = 0.1;        // probability that one gene of a child is mutated
  double crossover = 0.9;       // probability that two parents are recombined rather than copied
  int tournament = 2;           // contestants per selection
  int elite = 2;                // best individuals copied unchanged into the next generation
  double crossover_eta = 15.0;  // SBX distribution index: larger keeps children closer to their parents
  double mutation_eta = 20.0;   // polynomial mutation distribution index: larger makes smaller steps
  std::uint64_t seed = 1;
};

struct GaBounds {
  std::vector<double> lower, upper;  // one per gene, lower < upper, finite
};

struct GaResult {
  std::vector<double> best;
  double best_objective = 0.0;
  std::vector<double> convergence;  // best objective so far, after the initial generation and after each one
  std::uint64_t evaluations = 0;
};

using GaObjective = std::function<double(std::span<const double>)>;

// Minimises `objective` over the box. A non-finite objective value ranks below every finite one. Throws
// std::invalid_argument for empty or inverted bounds and for options out of range (population < elite + 2, a
// probability outside [0, 1], tournament < 1, negative generations or distribution indices).
GaResult minimize_ga(const GaObjective& objective, const GaBounds& bounds, const GaOptions& options);

}  // namespace imubridge::estimator
