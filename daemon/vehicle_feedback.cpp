#include "daemon/vehicle_feedback.hpp"

#include <cmath>
#include <stdexcept>

#include "protocol/imu_frame.hpp"
#include "protocol/xbee.hpp"

namespace imubridge::daemon {

VehicleFeedback::VehicleFeedback(protocol::WireFormat format, const VehicleFeedbackConfig& config)
    : format_(format), config_(config) {
  if (!config.enabled) return;
  if (format == protocol::WireFormat::mavlink) {
    throw std::invalid_argument(
        "vehicle feedback is not supported on MAVLink links: no standard message carries a body-frame horizontal "
        "velocity without attitude and vertical velocity");
  }
  if (!(config.rate_hz > 0) || !std::isfinite(config.rate_hz)) {
    throw std::invalid_argument("vehicle feedback rate must be a positive number of Hz, not " +
                                std::to_string(config.rate_hz));
  }
  period_ns_ = std::llround(1e9 / config.rate_hz);
}

std::optional<std::vector<std::uint8_t>> VehicleFeedback::on_estimate(const store::Estimate& estimate,
                                                                      std::int64_t mono_ns) {
  if (!config_.enabled) return std::nullopt;
  const double sx = std::sqrt(estimate.var_vx), sy = std::sqrt(estimate.var_vy);  // NaN for a negative variance
  if (!std::isfinite(estimate.vx) || !std::isfinite(estimate.vy) || !std::isfinite(sx) || !std::isfinite(sy)) {
    ++not_finite_;
    return std::nullopt;
  }
  if (last_sent_ns_ && mono_ns - *last_sent_ns_ < period_ns_) {
    ++rate_limited_;
    return std::nullopt;
  }
  last_sent_ns_ = mono_ns;
  ++sent_;

  // Stamped with the device time of the sample the estimate describes, so the vehicle can line it up with its own
  // measurements whatever the radio's latency.
  const double t_us = estimate.t_s * 1e6;
  const protocol::imu::Frame frame{
      .seq = seq_++,
      .device_time_us = t_us > 0 && std::isfinite(t_us) ? static_cast<std::uint64_t>(std::llround(t_us)) : 0,
      .payload = protocol::imu::VelocityEstimate{static_cast<float>(estimate.vx), static_cast<float>(estimate.vy),
                                                 static_cast<float>(sx), static_cast<float>(sy)}};
  std::vector<std::uint8_t> bytes;
  protocol::imu::encode(frame, bytes);
  if (format_ == protocol::WireFormat::imubridge) return bytes;

  namespace xbee = protocol::xbee;
  const xbee::Frame tx{.frame_type = xbee::kTxRequest,
                       .body = xbee::TxRequest{.frame_id = 0,  // 0: no TX status frames back, at rate_hz
                                               .destination64 = config_.xbee_destination64,
                                               .destination16 = 0xFFFE,  // unknown: the radio looks it up
                                               .payload = std::move(bytes)}};
  std::vector<std::uint8_t> out;
  xbee::encode(tx, format_ == protocol::WireFormat::xbee_escaped ? xbee::ApiMode::escaped : xbee::ApiMode::unescaped,
               out);
  return out;
}

nlohmann::json VehicleFeedback::counters() const {
  return {{"sent", sent_}, {"rate_limited", rate_limited_}, {"not_finite", not_finite_}};
}

}  // namespace imubridge::daemon
