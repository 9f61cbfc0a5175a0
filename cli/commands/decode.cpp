// `imubridge decode`: print every frame of a capture as one JSON object per line, then the decoder's counters on
// stderr. For inspecting what a radio or flight controller actually sends.
#include <CLI/CLI.hpp>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "cli/command.hpp"
#include "protocol/hex.hpp"
#include "protocol/imu_frame.hpp"
#include "protocol/mavlink.hpp"
#include "protocol/xbee.hpp"
#include "protocol/xbee_imu_reassembler.hpp"

namespace imubridge::cli {
namespace {

using nlohmann::json;
namespace proto = imubridge::protocol;

void print_line(const json& j) {
  const std::string line = j.dump() + '\n';
  std::fwrite(line.data(), 1, line.size(), stdout);
}

// One decoding pipeline per protocol: feed bytes, print frames, report counters.
class CaptureDecoder {
 public:
  virtual ~CaptureDecoder() = default;
  virtual void feed(std::span<const std::uint8_t> bytes) = 0;
  virtual json finish() = 0;  // the counters, after end of stream
};

class ImuCaptureDecoder final : public CaptureDecoder {
 public:
  void feed(std::span<const std::uint8_t> bytes) override {
    frames_.clear();
    decoder_.feed(bytes, frames_);
    for (const auto& frame : frames_) print_line(frame);
  }
  json finish() override {
    frames_.clear();
    decoder_.finish(frames_);
    for (const auto& frame : frames_) print_line(frame);
    return {{"imubridge", decoder_.counters()}};
  }

 private:
  proto::imu::Decoder decoder_;
  std::vector<proto::imu::Frame> frames_;
};

class XbeeCaptureDecoder final : public CaptureDecoder {
 public:
  explicit XbeeCaptureDecoder(proto::xbee::ApiMode mode) : decoder_(mode) {}
  void feed(std::span<const std::uint8_t> bytes) override {
    frames_.clear();
    decoder_.feed(bytes, frames_);
    print_frames();
  }
  json finish() override {
    frames_.clear();
    decoder_.finish(frames_);
    print_frames();
    inner_.clear();
    reassembler_.finish(inner_);
    print_inner();
    return {{"xbee", decoder_.counters()}, {"imubridge", reassembler_.counters()}};
  }

 private:
  void print_frames() {
    for (const auto& frame : frames_) {
      print_line(frame);
      // IMU frames travel inside RX packets: print them too, tagged with the radio they came from.
      if (const auto* rx = std::get_if<proto::xbee::RxPacket>(&frame.body)) {
        inner_.clear();
        reassembler_.on_rx(*rx, inner_);
        print_inner();
      }
    }
  }
  void print_inner() {
    for (const auto& sourced : inner_) {
      json j = sourced.frame;
      j["source64"] = proto::hex(sourced.source64, 8);
      print_line(j);
    }
  }

  proto::xbee::Decoder decoder_;
  proto::XbeeImuReassembler reassembler_;
  std::vector<proto::xbee::Frame> frames_;
  std::vector<proto::XbeeImuReassembler::SourcedFrame> inner_;
};

class MavlinkCaptureDecoder final : public CaptureDecoder {
 public:
  void feed(std::span<const std::uint8_t> bytes) override {
    messages_.clear();
    decoder_.feed(bytes, messages_);
    for (const auto& message : messages_) print_line(message);
  }
  json finish() override {
    messages_.clear();
    decoder_.finish(messages_);
    for (const auto& message : messages_) print_line(message);
    return {{"mavlink", decoder_.counters()}};
  }

 private:
  proto::mavlink::Decoder decoder_;
  std::vector<proto::mavlink::Message> messages_;
};

std::unique_ptr<CaptureDecoder> make_decoder(const std::string& protocol) {
  if (protocol == "imubridge") return std::make_unique<ImuCaptureDecoder>();
  if (protocol == "xbee") return std::make_unique<XbeeCaptureDecoder>(proto::xbee::ApiMode::unescaped);
  if (protocol == "xbee-escaped") return std::make_unique<XbeeCaptureDecoder>(proto::xbee::ApiMode::escaped);
  return std::make_unique<MavlinkCaptureDecoder>();
}

struct DecodeOptions {
  std::string protocol = "imubridge";
  std::string path;
};

int run_decode(const DecodeOptions& options) {
  FILE* in = options.path == "-" ? stdin : std::fopen(options.path.c_str(), "rb");
  if (in == nullptr) throw std::runtime_error("cannot open " + options.path + ": " + std::strerror(errno));
  std::unique_ptr<FILE, int (*)(FILE*)> closer(in == stdin ? nullptr : in, &std::fclose);
  auto decoder = make_decoder(options.protocol);
  std::vector<std::uint8_t> buffer(64 * 1024);
  for (;;) {
    const std::size_t n = std::fread(buffer.data(), 1, buffer.size(), in);
    if (n > 0) decoder->feed(std::span(buffer).first(n));
    if (n < buffer.size()) {
      if (std::ferror(in)) throw std::runtime_error("read error on " + options.path + ": " + std::strerror(errno));
      break;
    }
  }
  const std::string counters = decoder->finish().dump() + '\n';
  std::fflush(stdout);
  std::fputs(counters.c_str(), stderr);
  return 0;
}

const RegisterCommand kDecode([](CLI::App& app) -> CommandRunner {
  auto options = std::make_shared<DecodeOptions>();
  auto* cmd =
      app.add_subcommand("decode", "Decode a capture file: one JSON object per frame on stdout, counters on stderr");
  cmd->add_option("--protocol,-p", options->protocol, "Wire format of the capture")
      ->check(CLI::IsMember({"imubridge", "xbee", "xbee-escaped", "mavlink"}))
      ->capture_default_str();
  cmd->add_option("file", options->path, "Capture file ('-' reads standard input)")->required();
  cmd->footer(
      "xbee-escaped is XBee API mode 2. IMU frames carried in XBee RX packets are printed after their packet,\n"
      "with the radio's 64-bit source address. Bad frames are skipped and counted, never fatal.");
  return [options] { return run_decode(*options); };
});

}  // namespace
}  // namespace imubridge::cli
