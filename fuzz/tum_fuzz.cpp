// libFuzzer target for a TUM reference trajectory ("t x y z qx qy qz qw") read by `imubridge import euroc
// --reference FILE --reference-format tum` (importers/euroc_import.hpp), velocity derived from its positions included.
// Input: the TUM file; the dataset's IMU file is a fixed valid one. What counts as a finding:
// fuzz/euroc_import_harness.hpp.
#include <cstdint>
#include <string_view>

#include "fuzz/euroc_import_harness.hpp"

namespace {

constexpr std::string_view kImuCsv =
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],"
    "a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n"
    "1403636579758560000,0.01,-0.02,0.03,9.81,0.1,-0.2\n"
    "1403636579763560000,0.011,-0.021,0.031,9.8,0.11,-0.21\n"
    "1403636579768560000,0.012,-0.022,0.032,9.79,0.12,-0.22\n";

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static imubridge::fuzz::EurocImportHarness harness;
  harness.import(kImuCsv, std::string_view(reinterpret_cast<const char*>(data), size),
                 imubridge::importers::ReferenceFormat::tum);
  return 0;
}
