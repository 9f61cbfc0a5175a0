#include "importers/position_derivative.hpp"

#include <Eigen/Cholesky>
#include <cmath>
#include <stdexcept>

#include "replay/text_table.hpp"

namespace imubridge::importers {

std::vector<std::optional<Eigen::Vector3d>> velocity_from_positions(std::span<const std::int64_t> t_ns,
                                                                    std::span<const Eigen::Vector3d> positions,
                                                                    double half_window_s) {
  if (t_ns.size() != positions.size()) throw std::invalid_argument("velocity_from_positions: lengths differ");
  const auto half_ns = static_cast<std::int64_t>(std::llround(half_window_s * 1e9));
  const auto window = static_cast<std::uint64_t>(half_ns);
  std::vector<std::optional<Eigen::Vector3d>> velocity(t_ns.size());
  std::size_t first = 0, last = 0;  // the window [first, last)
  for (std::size_t i = 0; i < t_ns.size(); ++i) {
    while (replay::elapsed_ns(t_ns[first], t_ns[i]) > window) ++first;
    while (last < t_ns.size() && replay::elapsed_ns(t_ns[i], t_ns[last]) <= window) ++last;
    if (last - first < 3) continue;
    // p(s) = a + b s + c s^2 with s = (t - t_i) / half_window, so the normal equations stay well conditioned.
    Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
    Eigen::Matrix3d rhs = Eigen::Matrix3d::Zero();  // one column per axis
    for (std::size_t j = first; j < last; ++j) {
      const double s = static_cast<double>(t_ns[j] - t_ns[i]) / static_cast<double>(half_ns);
      const Eigen::Vector3d basis(1, s, s * s);
      normal += basis * basis.transpose();
      rhs += basis * positions[j].transpose();
    }
    const Eigen::Matrix3d coefficients = normal.ldlt().solve(rhs);
    velocity[i] = coefficients.row(1).transpose() / (static_cast<double>(half_ns) * 1e-9);
  }
  return velocity;
}

}  // namespace imubridge::importers
