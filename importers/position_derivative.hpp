#pragma once
// Velocity from a reference that has positions only (motion capture, TUM files): the slope of a quadratic fitted by
// least squares to the positions within +-half_window of each sample, a Savitzky-Golay differentiator that works on
// the samples' own (possibly uneven) times. A quadratic trajectory gives its exact velocity; noise is averaged over
// the window, and at the ends of the data the window is one-sided.
#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

namespace imubridge::importers {

// t_ns strictly increasing. A sample with fewer than 3 positions in its window gets no velocity. Throws
// std::invalid_argument when the lengths differ.
std::vector<std::optional<Eigen::Vector3d>> velocity_from_positions(std::span<const std::int64_t> t_ns,
                                                                    std::span<const Eigen::Vector3d> positions,
                                                                    double half_window_s = 0.1);

}  // namespace imubridge::importers
