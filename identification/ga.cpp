#include "identification/ga.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>

namespace imubridge::estimator {
namespace {

// std::mt19937_64 is specified bit for bit by the standard; the conversion to [0, 1) is ours for the same reason.
class Random {
 public:
  explicit Random(std::uint64_t seed) : engine_(seed) {}
  double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }  // [0, 1), 53 random bits
  std::size_t index(std::size_t n) { return static_cast<std::size_t>(uniform() * static_cast<double>(n)); }

 private:
  std::mt19937_64 engine_;
};

struct Individual {
  std::vector<double> genes;
  double objective = 0.0;  // +inf stands for a non-finite value, so that it ranks last
};

void check(const GaBounds& b, const GaOptions& o) {
  if (b.lower.empty() || b.lower.size() != b.upper.size())
    throw std::invalid_argument("GA: bounds must be non-empty and of equal length");
  for (std::size_t i = 0; i < b.lower.size(); ++i) {
    if (!std::isfinite(b.lower[i]) || !std::isfinite(b.upper[i]) || !(b.lower[i] < b.upper[i]))
      throw std::invalid_argument("GA: gene " + std::to_string(i) + " needs finite bounds with lower < upper");
  }
  const auto probability = [](double p) { return p >= 0.0 && p <= 1.0; };
  if (o.elite < 0 || o.population < o.elite + 2) throw std::invalid_argument("GA: population must be >= elite + 2");
  if (o.generations < 0) throw std::invalid_argument("GA: generations must be >= 0");
  if (!probability(o.mutation) || !probability(o.crossover))
    throw std::invalid_argument("GA: mutation and crossover probabilities must be in [0, 1]");
  if (o.tournament < 1) throw std::invalid_argument("GA: tournament size must be >= 1");
  if (!(o.crossover_eta >= 0.0) || !(o.mutation_eta >= 0.0))
    throw std::invalid_argument("GA: distribution indices must be >= 0");
}

// Bounded SBX on one gene of two parents: the children spread around the parents as a one-point crossover of binary
// strings would, with a spread distribution truncated so that neither child leaves [lo, hi].
void simulated_binary_crossover(double& a, double& b, double lo, double hi, double eta, Random& rng) {
  const double y1 = std::min(a, b), y2 = std::max(a, b);
  if (y2 - y1 <= 1e-14 * (hi - lo)) return;  // identical genes: nothing to spread
  const double u = rng.uniform();
  const double exponent = 1.0 / (eta + 1.0);
  const auto spread = [&](double beta) {
    const double alpha = 2.0 - std::pow(beta, -(eta + 1.0));
    return u <= 1.0 / alpha ? std::pow(u * alpha, exponent) : std::pow(1.0 / (2.0 - u * alpha), exponent);
  };
  double c1 = 0.5 * ((y1 + y2) - spread(1.0 + 2.0 * (y1 - lo) / (y2 - y1)) * (y2 - y1));
  double c2 = 0.5 * ((y1 + y2) + spread(1.0 + 2.0 * (hi - y2) / (y2 - y1)) * (y2 - y1));
  c1 = std::clamp(c1, lo, hi);
  c2 = std::clamp(c2, lo, hi);
  if (rng.uniform() < 0.5) std::swap(c1, c2);
  a = c1;
  b = c2;
}

// Bounded polynomial mutation: a step whose distribution is polynomial and truncated at the bounds, so the gene
// stays inside [lo, hi] and small steps are far more likely than large ones.
double polynomial_mutation(double y, double lo, double hi, double eta, Random& rng) {
  const double span = hi - lo;
  const double u = rng.uniform();
  const double exponent = 1.0 / (eta + 1.0);
  double step;
  if (u < 0.5) {
    const double room = 1.0 - (y - lo) / span;
    step = std::pow(2.0 * u + (1.0 - 2.0 * u) * std::pow(room, eta + 1.0), exponent) - 1.0;
  } else {
    const double room = 1.0 - (hi - y) / span;
    step = 1.0 - std::pow(2.0 * (1.0 - u) + 2.0 * (u - 0.5) * std::pow(room, eta + 1.0), exponent);
  }
  return std::clamp(y + step * span, lo, hi);
}

const Individual& tournament(const std::vector<Individual>& population, int size, Random& rng) {
  const Individual* winner = &population[rng.index(population.size())];
  for (int i = 1; i < size; ++i) {
    const Individual& contender = population[rng.index(population.size())];
    if (contender.objective < winner->objective) winner = &contender;
  }
  return *winner;
}

void rank(std::vector<Individual>& population) {
  std::stable_sort(population.begin(), population.end(),
                   [](const Individual& a, const Individual& b) { return a.objective < b.objective; });
}

}  // namespace

GaResult minimize_ga(const GaObjective& objective, const GaBounds& bounds, const GaOptions& options) {
  check(bounds, options);
  const std::size_t genes = bounds.lower.size();
  const auto population_size = static_cast<std::size_t>(options.population);
  Random rng(options.seed);
  GaResult result;
  const auto evaluate = [&](Individual& individual) {
    const double value = objective(individual.genes);
    individual.objective = std::isfinite(value) ? value : std::numeric_limits<double>::infinity();
    ++result.evaluations;
  };

  std::vector<Individual> population(population_size);
  for (Individual& individual : population) {
    individual.genes.resize(genes);
    for (std::size_t i = 0; i < genes; ++i)
      individual.genes[i] = bounds.lower[i] + (bounds.upper[i] - bounds.lower[i]) * rng.uniform();
    evaluate(individual);
  }
  rank(population);
  result.convergence.push_back(population.front().objective);

  std::vector<Individual> next;
  for (int generation = 0; generation < options.generations; ++generation) {
    next.assign(population.begin(), population.begin() + options.elite);
    while (next.size() < population_size) {
      Individual a = tournament(population, options.tournament, rng);
      Individual b = tournament(population, options.tournament, rng);
      if (rng.uniform() < options.crossover) {
        for (std::size_t i = 0; i < genes; ++i) {
          if (rng.uniform() < 0.5)
            simulated_binary_crossover(a.genes[i], b.genes[i], bounds.lower[i], bounds.upper[i], options.crossover_eta,
                                       rng);
        }
      }
      for (Individual* child : {&a, &b}) {
        for (std::size_t i = 0; i < genes; ++i) {
          if (rng.uniform() < options.mutation)
            child->genes[i] =
                polynomial_mutation(child->genes[i], bounds.lower[i], bounds.upper[i], options.mutation_eta, rng);
        }
      }
      evaluate(a);
      next.push_back(std::move(a));
      if (next.size() < population_size) {
        evaluate(b);
        next.push_back(std::move(b));
      }
    }
    population.swap(next);
    rank(population);
    result.convergence.push_back(population.front().objective);
  }
  result.best = population.front().genes;
  result.best_objective = population.front().objective;
  return result;
}

}  // namespace imubridge::estimator
