// libFuzzer target for the PX4 ULog reader (importers/ulog.hpp) behind `imubridge import ulog`. Input: a ULog file.
// A finding is a crash, a sanitizer report or an exception other than ParseError: damage in the data section must
// end reading there (Log::damage), anything else must be refused in one line.
#include <cstdint>
#include <span>

#include "importers/ulog.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const auto log = imubridge::importers::ulog::parse(std::span(data, size));
    for (const auto& topic : log.topics) {  // every record's every scalar is readable
      for (std::size_t r = 0; r < topic.size(); ++r) {
        for (std::size_t l = 0; l < topic.leaves.size(); ++l) (void)topic.value(r, l);
        (void)topic.timestamp(r);
      }
    }
    (void)nlohmann::json(log.info).dump();  // the metadata the import stores must serialise
    (void)nlohmann::json(log.multi_info).dump();
  } catch (const imubridge::importers::ulog::ParseError&) {
  }
  return 0;
}
