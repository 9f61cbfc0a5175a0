#include "pipeline/land_detector.hpp"

#include <algorithm>
#include <variant>

#include "protocol/mavlink_messages.hpp"

namespace imubridge::pipeline {

std::optional<bool> mavlink_landed(const protocol::mavlink::Message& m,
                                   const std::optional<protocol::mavlink::ImuSource>& imu) {
  namespace mavlink = protocol::mavlink;
  if (m.msgid != mavlink::ExtendedSysState::kId || !imu || m.sysid != imu->sysid) return std::nullopt;
  const std::optional<mavlink::Decoded> decoded = mavlink::decode(m);
  const auto* state = decoded ? std::get_if<mavlink::ExtendedSysState>(&*decoded) : nullptr;
  if (!state) return std::nullopt;
  return state->landed_state == static_cast<std::uint8_t>(mavlink::LandedState::on_ground);
}

std::vector<MavlinkLandDetectorChanges::Change> MavlinkLandDetectorChanges::after(const LinkDecoder& decoder) {
  std::vector<Change> out;
  const auto imu = decoder.mavlink_imu();
  for (const protocol::mavlink::Message& m : decoder.mavlink_messages()) {
    const std::optional<bool> landed = mavlink_landed(m, imu);
    if (!landed) continue;
    if (landed_ && *landed_ != *landed) out.push_back({*landed, m.sysid});
    landed_ = landed;
  }
  return out;
}

std::vector<store::Event> land_detector_events(std::span<const store::Event> events) {
  std::vector<store::Event> out;
  for (const store::Event& e : events) {
    if (e.kind == "takeoff" || e.kind == "landing") out.push_back(e);
  }
  std::stable_sort(out.begin(), out.end(),
                   [](const store::Event& a, const store::Event& b) { return a.mono_ns < b.mono_ns; });
  return out;
}

StoredLandDetector::StoredLandDetector(std::span<const store::Event> events) : events_(land_detector_events(events)) {}

std::vector<StoredLandDetector::Change> StoredLandDetector::until(std::int64_t mono_ns) {
  std::vector<Change> out;
  for (; next_ < events_.size() && events_[next_].mono_ns <= mono_ns; ++next_) {
    out.push_back({events_[next_].link_id, events_[next_].kind == "landing"});
  }
  return out;
}

}  // namespace imubridge::pipeline
