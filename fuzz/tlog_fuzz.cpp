// libFuzzer target for the MAVLink telemetry log reader (importers/tlog.hpp) behind `imubridge import tlog`. Input: a
// tlog. A finding is a crash, a sanitizer report, an exception other than ParseError, or a Log that does not account
// for the file: its records and damaged stretches, in order, must tile every byte of it, each record's frame must pass
// the MAVLink checks (or be of an id no dialect here knows, or a known id's other layout), and the damage must read as
// one line.
#include <algorithm>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "fuzz/fuzz_require.hpp"
#include "protocol/mavlink.hpp"
#include "importers/tlog.hpp"

namespace tlog = imubridge::importers::tlog;
namespace mavlink = imubridge::protocol::mavlink;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const tlog::Log log = tlog::parse(std::vector<std::uint8_t>(data, data + size));
    FUZZ_REQUIRE(!log.records.empty());
    std::size_t at = 0, record = 0, damage = 0;
    std::uint64_t unverified = 0;
    while (at < size) {  // records and damage, whichever starts here, one after another to the end
      if (record < log.records.size() && log.records[record].offset == at) {
        const tlog::Record& r = log.records[record++];
        const auto check = mavlink::check_frame(log.frame(r));
        FUZZ_REQUIRE(check.size == r.size);
        using Status = mavlink::FrameCheck::Status;
        FUZZ_REQUIRE(check.status == Status::frame || check.status == Status::unverified ||
                     check.status == Status::other_layout);
        unverified += check.status != Status::frame;
        std::vector<std::uint8_t> again;
        tlog::append_record(again, r.time_us, log.frame(r));
        FUZZ_REQUIRE(std::equal(again.begin(), again.end(), data + r.offset));
        at += tlog::kTimeSize + r.size;
      } else {
        FUZZ_REQUIRE(damage < log.damage.size() && log.damage[damage].offset == at && log.damage[damage].bytes > 0);
        FUZZ_REQUIRE(log.damage[damage].record == record);
        at += log.damage[damage++].bytes;
      }
    }
    FUZZ_REQUIRE(at == size && record == log.records.size() && damage == log.damage.size());
    FUZZ_REQUIRE(unverified == log.unverified);
    if (const auto summary = log.damage_summary()) FUZZ_REQUIRE(summary->find('\n') == std::string::npos);
  } catch (const tlog::ParseError&) {
  }
  return 0;
}
