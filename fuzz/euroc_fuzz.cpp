// libFuzzer target for `imubridge import euroc` on an EuRoC/ASL dataset (importers/euroc_import.hpp): the IMU's
// mav0/imu0/data.csv and, after a form feed (\f) in the input, the ground truth
// mav0/state_groundtruth_estimate0/data.csv. Without a form feed the dataset has no ground truth. What counts as a
// finding: fuzz/euroc_import_harness.hpp.
#include <cstdint>
#include <optional>
#include <string_view>

#include "fuzz/euroc_import_harness.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static imubridge::fuzz::EurocImportHarness harness;
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  const std::size_t split = input.find('\f');
  std::optional<std::string_view> ground_truth;
  if (split != std::string_view::npos) ground_truth = input.substr(split + 1);
  harness.import(input.substr(0, split), ground_truth, imubridge::importers::ReferenceFormat::euroc_gt);
  return 0;
}
