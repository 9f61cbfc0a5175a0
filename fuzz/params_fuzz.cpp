// libFuzzer target for reading PARAMS.json (estimator/params.hpp), the way estimator::parse_params() reads it for
// `imubridge run --params`, replay and evaluate. Input: the file's text. Reading either gives ModelParams or throws
// nlohmann's json::exception (not JSON, a value of the wrong type) or std::invalid_argument (the strict checks);
// parse_params() would fold any exception into std::invalid_argument, so the target calls what it wraps to let any
// other exception escape as a finding. ModelParams read from a file write as JSON (save_params()) that reads back
// equal.
#include <cstdint>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string_view>

#include "estimator/params.hpp"

using imubridge::estimator::ModelParams;
using nlohmann::json;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  ModelParams params;
  try {
    params = json::parse(text).get<ModelParams>();
  } catch (const json::exception&) {
    return 0;
  } catch (const std::invalid_argument&) {
    return 0;
  }
  if (json::parse(json(params).dump(2)).get<ModelParams>() != params) std::abort();
  return 0;
}
