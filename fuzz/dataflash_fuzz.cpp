// libFuzzer target for the ArduPilot DataFlash reader (importers/dataflash.hpp) behind `imubridge import dataflash`.
// Input: a DataFlash log. A finding is a crash, a sanitizer report, an exception other than ParseError, or a Log that
// does not hold together: every message's records fill its data exactly, every field of every record is readable,
// and damage reads as one line.
#include <cstdint>
#include <span>
#include <string>

#include "fuzz/fuzz_require.hpp"
#include "importers/dataflash.hpp"

namespace dataflash = imubridge::importers::dataflash;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const dataflash::Log log = dataflash::parse(std::span(data, size));
    std::uint64_t records = 0;
    for (const auto& [type, m] : log.messages) {
      FUZZ_REQUIRE(m.type == type && m.length >= dataflash::kHeaderSize);
      FUZZ_REQUIRE(m.data.size() == m.size() * (m.length - dataflash::kHeaderSize));
      records += m.size();
      for (std::size_t r = 0; r < m.size(); ++r) {
        for (std::size_t f = 0; f < m.fields.size(); ++f) {
          (void)m.value(r, f);
          (void)m.integer(r, f);
          FUZZ_REQUIRE(m.text(r, f).size() <= dataflash::field_size(m.fields[f].type));
        }
      }
    }
    FUZZ_REQUIRE(records <= log.records);
    if (log.damage) FUZZ_REQUIRE(log.damage->find('\n') == std::string::npos);
  } catch (const dataflash::ParseError&) {
  }
  return 0;
}
