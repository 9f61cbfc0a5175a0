#pragma once
// Seeded randomness that is bit-identical wherever the standard library is: std::mt19937_64 is fully specified by
// the standard, std::uniform_real_distribution and std::normal_distribution are not, so the conversions are ours.
#include <cstdint>
#include <random>

namespace imubridge::sim {

class Rng {
 public:
  explicit Rng(std::uint64_t seed) : engine_(seed) {}
  // An independent generator for one purpose (flight plan, sensor noise, ...): changing how many numbers one
  // purpose draws must not shift what another sees.
  static Rng stream(std::uint64_t seed, std::uint64_t stream_id);

  double uniform();                      // [0, 1), 53 random bits
  double uniform(double lo, double hi);  // [lo, hi)
  double normal();                       // standard normal, Marsaglia's polar method

 private:
  std::mt19937_64 engine_;
  double spare_normal_ = 0.0;  // the polar method makes normals in pairs
  bool has_spare_ = false;
};

}  // namespace imubridge::sim
