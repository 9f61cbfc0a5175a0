#pragma once
// The velocity estimate sent back to the vehicle over the link it came from, at most config.rate_hz times a second.
// Frames per wire format and why MAVLink links get none: docs/outputs.md, "Velocity feedback to the vehicle".
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <vector>

#include "daemon/config.hpp"
#include "protocol/wire_format.hpp"
#include "store/records.hpp"

namespace imubridge::daemon {

class VehicleFeedback {
 public:
  // Throws std::invalid_argument when feedback is enabled on a MAVLink link (no standard message carries this
  // estimate) or with a rate that is not a positive number.
  VehicleFeedback(protocol::WireFormat format, const VehicleFeedbackConfig& config);

  // The bytes to write to the link for this estimate, or nothing: feedback disabled, less than 1 / rate_hz since the
  // last estimate sent (on the estimate clock, mono_ns), or a velocity or variance that is not a finite number (such an
  // estimate does not use up the slot). imubridge links get a velocity_estimate frame numbered by its own counter; XBee
  // links the same frame inside a TX request to config.xbee_destination64, in the link's API mode.
  std::optional<std::vector<std::uint8_t>> on_estimate(const store::Estimate& estimate, std::int64_t mono_ns);

  nlohmann::json counters() const;  // {"sent", "rate_limited", "not_finite"}

 private:
  protocol::WireFormat format_;
  VehicleFeedbackConfig config_;
  std::int64_t period_ns_ = 0;
  std::optional<std::int64_t> last_sent_ns_;
  std::uint16_t seq_ = 0;  // of the next frame
  std::uint64_t sent_ = 0, rate_limited_ = 0, not_finite_ = 0;
};

}  // namespace imubridge::daemon
