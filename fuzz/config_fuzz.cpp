// libFuzzer target for the TOML configuration of `imubridge run` (daemon/config_file.hpp). Input: the file's text.
// parse_config() either returns a Config or throws std::invalid_argument (its one documented error); any other
// exception escapes to libFuzzer as a finding. A Config it returns writes as TOML (the session's config snapshot) that
// parses again to a Config writing the same TOML.
#include <cstdint>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <string_view>

#include "daemon/config_file.hpp"

using imubridge::daemon::Config;
using imubridge::daemon::parse_config;
using imubridge::daemon::to_toml;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  Config config;
  try {
    config = parse_config(text, "fuzz.toml");
  } catch (const std::invalid_argument&) {
    return 0;
  }
  const std::string snapshot = to_toml(config);
  if (to_toml(parse_config(snapshot, "snapshot.toml")) != snapshot) std::abort();
  return 0;
}
