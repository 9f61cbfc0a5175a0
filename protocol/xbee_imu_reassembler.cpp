#include "protocol/xbee_imu_reassembler.hpp"

namespace imubridge::protocol {

void XbeeImuReassembler::on_rx(const xbee::RxPacket& rx, std::vector<SourcedFrame>& out) {
  decoded_.clear();
  sources_[rx.source64].feed(rx.payload, decoded_);
  for (imu::Frame& frame : decoded_) out.push_back({rx.source64, std::move(frame)});
}

void XbeeImuReassembler::finish() {
  for (auto& [source64, decoder] : sources_) decoder.finish();
}

DecoderCounters XbeeImuReassembler::counters() const {
  DecoderCounters sum;
  for (const auto& [source64, decoder] : sources_) sum += decoder.counters();
  return sum;
}

}  // namespace imubridge::protocol
