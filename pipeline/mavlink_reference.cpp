#include "pipeline/mavlink_reference.hpp"

#include <algorithm>
#include <cmath>
#include <variant>

#include "protocol/mavlink_messages.hpp"

namespace imubridge::pipeline {
namespace {

namespace mavlink = protocol::mavlink;

// Attitudes further apart than this are not interpolated across for a reference row.
constexpr std::uint64_t kMaxAttitudeGapUs = 500'000;
// Bounds for a live link that runs for days: attitudes kept to interpolate in, positions waiting for an attitude.
constexpr std::size_t kKeptAttitudes = 4096, kMaxWaiting = 4096, kMaxSenders = 16;

bool finite(const std::array<double, 3>& v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

}  // namespace

std::map<std::string, std::uint64_t> MavlinkReference::skipped() const {
  std::map<std::string, std::uint64_t> all = skipped_;
  if (sender_) {
    if (const auto a = attitudes_.find(*sender_); a != attitudes_.end()) {
      for (const auto& [reason, n] : a->second.skipped) all[reason] += n;
    }
  }
  return all;
}

std::string MavlinkReference::source() const {
  const std::optional<Component> sender = sender_ ? sender_ : choice_.sender;
  if (!sender) return "";
  const auto a = attitudes_.find(*sender);
  const bool quaternions = choice_.quaternions.value_or(a != attitudes_.end() && !a->second.quaternions.empty());
  return std::string("LOCAL_POSITION_NED + ") + (quaternions ? "ATTITUDE_QUATERNION" : "ATTITUDE") + " from system " +
         std::to_string(sender->first) + ", component " + std::to_string(sender->second);
}

void MavlinkReference::add_attitude(Attitudes& attitudes, bool quaternion, Attitude a) {
  std::deque<Attitude>& to = quaternion ? attitudes.quaternions : attitudes.eulers;
  if (!(std::abs(a.q.norm() - 1) <= 1e-2)) {  // also NaN: an estimator not yet initialised
    ++attitudes.skipped["attitude quaternion not of unit length"];
  } else if (!to.empty() && a.key() <= to.back().key()) {
    ++attitudes.skipped["attitude time not after the previous one's"];
  } else {
    a.q.normalize();
    to.push_back(a);
    if (to.size() > kKeptAttitudes) to.pop_front();
  }
}

const std::deque<MavlinkReference::Attitude>& MavlinkReference::attitudes() const {
  static const std::deque<Attitude> kNone;
  const auto a = sender_ ? attitudes_.find(*sender_) : attitudes_.end();
  if (a == attitudes_.end()) return kNone;
  const bool quaternions = choice_.quaternions.value_or(!a->second.quaternions.empty());
  return quaternions ? a->second.quaternions : a->second.eulers;
}

void MavlinkReference::on_message(const mavlink::Message& m, std::int64_t t_ns,
                                  std::vector<store::ReferenceRow>& rows) {
  const Component from{m.sysid, m.compid};
  const bool position = m.msgid == mavlink::LocalPositionNed::kId;
  if (!position && m.msgid != mavlink::AttitudeQuaternion::kId && m.msgid != mavlink::Attitude::kId) return;
  if (!sender_) {
    if (choice_.sender) {
      sender_ = choice_.sender;
    } else if (position) {
      sender_ = preferred_.value_or(from);
    }
  }
  // Before the sender is known (no position yet) every sender's attitudes are kept; after, only its own.
  if (sender_ && from != *sender_) return;
  if (!sender_ && !attitudes_.contains(from) && attitudes_.size() >= kMaxSenders) return;
  const std::optional<mavlink::Decoded> decoded = mavlink::decode(m);
  if (!decoded) return;
  if (const auto* lp = std::get_if<mavlink::LocalPositionNed>(&*decoded)) {
    waiting_.push_back(
        {m.clock_epoch, std::uint64_t{lp->time_boot_ms} * 1000, t_ns, {lp->x, lp->y, lp->z}, {lp->vx, lp->vy, lp->vz}});
  } else if (const auto* aq = std::get_if<mavlink::AttitudeQuaternion>(&*decoded)) {
    add_attitude(
        attitudes_[from], true,
        {m.clock_epoch, std::uint64_t{aq->time_boot_ms} * 1000, Eigen::Quaterniond(aq->q1, aq->q2, aq->q3, aq->q4)});
  } else if (const auto* e = std::get_if<mavlink::Attitude>(&*decoded)) {
    // ZYX intrinsic: yaw about z, then pitch about the new y, then roll about the new x; body -> NED.
    const Eigen::Quaterniond q = Eigen::AngleAxisd(e->yaw, Eigen::Vector3d::UnitZ()) *
                                 Eigen::AngleAxisd(e->pitch, Eigen::Vector3d::UnitY()) *
                                 Eigen::AngleAxisd(e->roll, Eigen::Vector3d::UnitX());
    add_attitude(attitudes_[from], false, {m.clock_epoch, std::uint64_t{e->time_boot_ms} * 1000, q});
  }
  if (sender_ && attitudes_.size() > 1) std::erase_if(attitudes_, [&](const auto& a) { return a.first != *sender_; });
  resolve(rows, false);
}

void MavlinkReference::finish(std::vector<store::ReferenceRow>& rows) { resolve(rows, true); }

void MavlinkReference::resolve(std::vector<store::ReferenceRow>& rows, bool at_end) {
  // In arrival order, so "not after the previous row's" is judged as it would be over the whole stream. Attitudes
  // come in increasing time (others are dropped), so once one at or after a position has come, the attitudes around
  // it are final.
  while (!waiting_.empty()) {
    const std::deque<Attitude>& a = attitudes();
    const bool ready =
        at_end || waiting_.size() > kMaxWaiting || (!a.empty() && a.back().key() >= waiting_.front().key());
    if (!ready) return;
    resolve_one(waiting_.front(), rows);
    waiting_.pop_front();
  }
}

void MavlinkReference::resolve_one(const Position& p, std::vector<store::ReferenceRow>& rows) {
  if (!finite(p.position)) {
    ++skipped_["position not a finite number"];
    return;
  }
  const std::deque<Attitude>& attitude = attitudes();
  const auto key = p.key();
  std::optional<Eigen::Quaterniond> a;
  const auto it = std::lower_bound(attitude.begin(), attitude.end(), key,
                                   [](const Attitude& x, const auto& k) { return x.key() < k; });
  if (it != attitude.end() && it->key() == key) {
    a = it->q;
  } else if (it != attitude.end() && it != attitude.begin() && std::prev(it)->epoch == p.epoch &&
             it->epoch == p.epoch && it->device_us - std::prev(it)->device_us <= kMaxAttitudeGapUs) {
    const Attitude& before = *std::prev(it);
    a = before.q.slerp(
        static_cast<double>(p.device_us - before.device_us) / static_cast<double>(it->device_us - before.device_us),
        it->q);
  }
  if (!a) {
    ++skipped_["no attitude around it"];
    return;
  }
  if (last_row_t_ns_ && p.t_ns <= *last_row_t_ns_) {
    ++skipped_["timestamp not after the previous row's"];
    return;
  }
  last_row_t_ns_ = p.t_ns;
  ++rows_;
  store::ReferenceRow& row = rows.emplace_back(
      store::ReferenceRow{.t_ns = p.t_ns, .position = p.position, .quat_wxyz = {a->w(), a->x(), a->y(), a->z()}});
  if (finite(p.velocity)) row.velocity = p.velocity;
}

}  // namespace imubridge::pipeline
