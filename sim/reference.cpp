#include "sim/reference.hpp"

#include <cmath>
#include <stdexcept>

namespace imubridge::sim {

ReferenceReceiver::ReferenceReceiver(const ReferenceConfig& config) : config_(config) {
  if (!(config.delay_s >= 0.0) || !(config.rate_hz >= 0.0) || !(config.velocity_quantum >= 0.0) ||
      !std::isfinite(config.delay_s) || !std::isfinite(config.rate_hz) || !std::isfinite(config.velocity_quantum))
    throw std::invalid_argument("reference: delay, rate and quantum must be finite and >= 0");
}

std::optional<ReferencePose> ReferenceReceiver::next(const TrueState& truth) {
  const double t = truth.time_s;
  past_.push_back({t, truth.position_ned, truth.velocity_ned});
  const double seen = t - config_.delay_s;  // the time the pose describes
  while (past_.size() > 2 && past_[1].t <= seen) past_.pop_front();
  if (past_.front().t > seen) return std::nullopt;
  if (config_.rate_hz > 0.0) {
    // On the rate's own grid from the first pose, so the spacing does not drift with the IMU's sample times; the
    // nanosecond tolerance keeps a stamp that falls on a sample time from slipping to the next one by rounding.
    constexpr double kTolerance = 1e-9;
    if (!first_stamp_) first_stamp_ = t;
    const auto stamp = [&](std::uint64_t n) { return *first_stamp_ + static_cast<double>(n) / config_.rate_hz; };
    if (t < stamp(stamps_) - kTolerance) return std::nullopt;
    while (stamp(stamps_) <= t + kTolerance) ++stamps_;
  }
  ReferencePose pose{.t = t, .attitude = truth.attitude};
  const Past& a = past_.front();
  const Past& b = past_.size() > 1 ? past_[1] : past_.front();
  const double f = b.t > a.t ? (seen - a.t) / (b.t - a.t) : 0.0;
  pose.position_ned = a.position + f * (b.position - a.position);
  pose.velocity_ned = a.velocity + f * (b.velocity - a.velocity);
  if (config_.velocity_quantum > 0.0)
    pose.velocity_ned =
        ((pose.velocity_ned / config_.velocity_quantum).array().round() * config_.velocity_quantum).matrix();
  return pose;
}

}  // namespace imubridge::sim
