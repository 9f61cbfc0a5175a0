#include "pipeline/link_decoder.hpp"

#include <algorithm>
#include <array>
#include <map>
#include <stdexcept>
#include <variant>

#include "protocol/imu_frame.hpp"
#include "protocol/mavlink.hpp"
#include "protocol/xbee.hpp"
#include "protocol/xbee_imu_reassembler.hpp"

namespace imubridge::pipeline {
namespace {

// MAVLink numbers messages per sending component with 8 bits; a sample's sequence is that number unwrapped.
class MavlinkSequences {
 public:
  std::uint64_t unwrap(const protocol::mavlink::Message& m) {
    auto [it, first] = last_.try_emplace(static_cast<std::uint16_t>(m.sysid << 8 | m.compid), m.seq);
    if (!first) it->second += static_cast<std::uint8_t>(m.seq - static_cast<std::uint8_t>(it->second));
    return it->second;
  }

 private:
  std::map<std::uint16_t, std::uint64_t> last_;
};

struct ImuLink {
  protocol::imu::Decoder decoder;
  std::vector<protocol::imu::Frame> frames;
};

struct XbeeLink {
  explicit XbeeLink(protocol::xbee::ApiMode mode) : decoder(mode) {}
  protocol::xbee::Decoder decoder;
  protocol::XbeeImuReassembler reassembler;
  std::vector<protocol::xbee::Frame> frames;
  std::vector<protocol::XbeeImuReassembler::SourcedFrame> imu_frames;
  std::vector<std::uint64_t> radios;  // in the order first heard
};

struct MavlinkLink {
  protocol::mavlink::Decoder decoder;
  MavlinkSequences sequences;
  std::vector<protocol::mavlink::Message> messages;
};

}  // namespace

struct LinkDecoder::Impl {
  protocol::WireFormat format;
  protocol::Calibration calibration;
  std::optional<protocol::mavlink::ImuSource> mavlink_imu;
  std::optional<MavlinkImuLock> lock{};
  std::variant<ImuLink, XbeeLink, MavlinkLink> link;
  std::uint64_t frames_without_sample = 0;

  void emit(const protocol::imu::Frame& frame, const protocol::SourceKey& source, std::int64_t t,
            std::vector<protocol::Sample>& out) {
    if (auto sample = protocol::to_sample(frame, calibration, source, t)) {
      out.push_back(*sample);
    } else {
      ++frames_without_sample;
    }
  }

  void take(ImuLink& l, std::int64_t t, std::vector<protocol::Sample>& out) {
    for (const auto& frame : l.frames) emit(frame, {}, t, out);
  }

  void take(XbeeLink& l, std::int64_t t, std::vector<protocol::Sample>& out) {
    for (const auto& frame : l.frames) {
      const auto* rx = std::get_if<protocol::xbee::RxPacket>(&frame.body);
      if (rx == nullptr) {  // TX status and the like: link management, not measurements
        ++frames_without_sample;
        continue;
      }
      l.imu_frames.clear();
      l.reassembler.on_rx(*rx, l.imu_frames);
      take_sourced(l, t, out);
    }
  }

  void take_sourced(XbeeLink& l, std::int64_t t, std::vector<protocol::Sample>& out) {
    for (const auto& sourced : l.imu_frames) {
      if (std::find(l.radios.begin(), l.radios.end(), sourced.source64) == l.radios.end()) {
        l.radios.push_back(sourced.source64);
      }
      emit(sourced.frame, {.radio = sourced.source64}, t, out);
    }
  }

  void take(MavlinkLink& l, std::int64_t t, std::vector<protocol::Sample>& out) {
    for (const auto& message : l.messages) {
      const std::uint64_t sequence = l.sequences.unwrap(message);
      auto sample = protocol::mavlink::to_sample(message, &calibration);
      if (sample && (mavlink_imu || lock)) {
        const std::optional<protocol::mavlink::ImuSource> source = protocol::mavlink::imu_source(message);
        if (!mavlink_imu && source && lock->admits(*source)) mavlink_imu = source;  // the first IMU heard
        if (source != mavlink_imu) sample.reset();
      }
      if (!sample) {
        ++frames_without_sample;
        continue;
      }
      sample->seq = sequence;
      sample->recv_mono_ns = t;
      out.push_back(*sample);
    }
  }
};

LinkDecoder::LinkDecoder(protocol::WireFormat format, const protocol::Calibration& calibration,
                         std::optional<protocol::mavlink::ImuSource> mavlink_imu)
    : impl_(std::make_unique<Impl>(Impl{format, calibration, mavlink_imu, std::nullopt, ImuLink{}, 0})) {
  if (!calibration.valid()) throw std::invalid_argument("invalid calibration (axis map, signs or scales)");
  switch (format) {
    case protocol::WireFormat::imubridge:
      break;
    case protocol::WireFormat::xbee:
      impl_->link.emplace<XbeeLink>(protocol::xbee::ApiMode::unescaped);
      break;
    case protocol::WireFormat::xbee_escaped:
      impl_->link.emplace<XbeeLink>(protocol::xbee::ApiMode::escaped);
      break;
    case protocol::WireFormat::mavlink:
      impl_->link.emplace<MavlinkLink>();
      break;
  }
}

LinkDecoder::~LinkDecoder() = default;
LinkDecoder::LinkDecoder(LinkDecoder&&) noexcept = default;
LinkDecoder& LinkDecoder::operator=(LinkDecoder&&) noexcept = default;

void LinkDecoder::lock_mavlink_imu(const MavlinkImuLock& lock) { impl_->lock = lock; }
std::optional<protocol::mavlink::ImuSource> LinkDecoder::mavlink_imu() const { return impl_->mavlink_imu; }
bool LinkDecoder::awaiting_mavlink_imu() const { return impl_->lock && !impl_->mavlink_imu; }

std::span<const std::uint64_t> LinkDecoder::radios() const {
  const auto* l = std::get_if<XbeeLink>(&impl_->link);
  return l ? std::span<const std::uint64_t>(l->radios) : std::span<const std::uint64_t>();
}

std::span<const protocol::mavlink::Message> LinkDecoder::mavlink_messages() const {
  const auto* l = std::get_if<MavlinkLink>(&impl_->link);
  return l ? std::span<const protocol::mavlink::Message>(l->messages) : std::span<const protocol::mavlink::Message>();
}

void LinkDecoder::feed(std::span<const std::uint8_t> chunk, std::int64_t recv_mono_ns,
                       std::vector<protocol::Sample>& out) {
  std::visit(
      [&](auto& l) {
        using L = std::decay_t<decltype(l)>;
        if constexpr (std::is_same_v<L, ImuLink>) {
          l.frames.clear();
          l.decoder.feed(chunk, l.frames);
        } else if constexpr (std::is_same_v<L, XbeeLink>) {
          l.frames.clear();
          l.decoder.feed(chunk, l.frames);
        } else {
          l.messages.clear();
          l.decoder.feed(chunk, l.messages);
        }
        impl_->take(l, recv_mono_ns, out);
      },
      impl_->link);
}

void LinkDecoder::finish(std::int64_t recv_mono_ns, std::vector<protocol::Sample>& out) {
  std::visit(
      [&](auto& l) {
        using L = std::decay_t<decltype(l)>;
        if constexpr (std::is_same_v<L, ImuLink>) {
          l.frames.clear();
          l.decoder.finish(l.frames);
          impl_->take(l, recv_mono_ns, out);
        } else if constexpr (std::is_same_v<L, XbeeLink>) {
          l.frames.clear();
          l.decoder.finish(l.frames);
          impl_->take(l, recv_mono_ns, out);
          l.imu_frames.clear();
          l.reassembler.finish(l.imu_frames);  // each radio's unfinished tail
          impl_->take_sourced(l, recv_mono_ns, out);
        } else {
          l.messages.clear();
          l.decoder.finish(l.messages);
          impl_->take(l, recv_mono_ns, out);
        }
      },
      impl_->link);
}

std::vector<std::pair<std::string, protocol::DecoderCounters>> LinkDecoder::counters() const {
  return std::visit(
      [](const auto& l) -> std::vector<std::pair<std::string, protocol::DecoderCounters>> {
        using L = std::decay_t<decltype(l)>;
        if constexpr (std::is_same_v<L, ImuLink>) {
          return {{"imubridge", l.decoder.counters()}};
        } else if constexpr (std::is_same_v<L, XbeeLink>) {
          return {{"xbee", l.decoder.counters()}, {"imubridge", l.reassembler.counters()}};
        } else {
          return {{"mavlink", l.decoder.counters()}};
        }
      },
      impl_->link);
}

std::uint64_t LinkDecoder::frames_without_sample() const { return impl_->frames_without_sample; }
protocol::WireFormat LinkDecoder::format() const { return impl_->format; }

}  // namespace imubridge::pipeline
