// Reads a MAVLink stream on stdin and writes its messages again as MAVLink 1 frames (`mavlink_reframe v1`) or as
// signed MAVLink 2 frames (`mavlink_reframe signed`), so the fuzzers' seeds hold every framing the decoder takes while
// the simulator sends unsigned MAVLink 2 only. Used by scripts/fuzz-corpus.
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <iterator>
#include <span>
#include <string_view>
#include <vector>

#include "protocol/mavlink.hpp"

namespace mavlink = imubridge::protocol::mavlink;

int main(int argc, char** argv) {
  const std::string_view framing = argc == 2 ? argv[1] : "";
  if (framing != "v1" && framing != "signed") {
    std::fprintf(stderr, "usage: mavlink_reframe v1|signed <mavlink.bin >reframed.bin\n");
    return 2;
  }
  const std::vector<std::uint8_t> in((std::istreambuf_iterator<char>(std::cin)), std::istreambuf_iterator<char>());
  std::vector<mavlink::Message> messages;
  mavlink::Decoder decoder;
  decoder.feed(in, messages);
  decoder.finish(messages);

  std::vector<std::uint8_t> out;
  for (const mavlink::Message& m : messages) {
    const mavlink::FrameOptions options{.version = static_cast<std::uint8_t>(framing == "v1" ? 1 : 2),
                                        .seq = m.seq,
                                        .sysid = m.sysid,
                                        .compid = m.compid,
                                        .sign = framing == "signed"};
    if (const auto typed = mavlink::decode(m)) {
      mavlink::encode(mavlink::make_message(*typed, options), out);
    } else {
      mavlink::encode(mavlink::make_message(m.msgid, std::span(m.payload).first(m.len), options), out);
    }
  }
  std::fwrite(out.data(), 1, out.size(), stdout);
  return 0;
}
