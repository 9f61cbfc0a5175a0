#include "protocol/xbee_imu_reassembler.hpp"

#include <utility>

namespace imubridge::protocol {

void XbeeImuReassembler::on_rx(const xbee::RxPacket& rx, std::vector<SourcedFrame>& out) {
  sources_[rx.source64].feed(rx.payload, decoded_);
  emit(rx.source64, out);
}

void XbeeImuReassembler::finish(std::vector<SourcedFrame>& out) {
  for (auto& [source64, decoder] : sources_) {
    decoder.finish(decoded_);
    emit(source64, out);
  }
}

DecoderCounters XbeeImuReassembler::counters() const {
  DecoderCounters sum;
  for (const auto& [source64, decoder] : sources_) sum += decoder.counters();
  return sum;
}

void XbeeImuReassembler::emit(std::uint64_t source64, std::vector<SourcedFrame>& out) {
  for (imu::Frame& frame : decoded_) out.push_back({source64, std::move(frame)});
  decoded_.clear();
}

}  // namespace imubridge::protocol
