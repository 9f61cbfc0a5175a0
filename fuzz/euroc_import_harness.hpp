#pragma once
// What fuzz/euroc_fuzz.cpp and fuzz/tum_fuzz.cpp share: `imubridge import euroc` (importers::import_euroc) on a dataset
// written from the fuzzer's input, into a scratch store. The import reads files only, so the input goes to a
// directory of the process's own that disappears at exit. It either imports or throws std::invalid_argument (a
// missing file, no usable row) or store::StoreError; any other exception escapes to libFuzzer as a finding.
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>

#include "importers/euroc_import.hpp"
#include "store/error.hpp"
#include "store/store.hpp"

namespace imubridge::fuzz {

class EurocImportHarness {
 public:
  EurocImportHarness() { std::filesystem::create_directories(imu_csv_.parent_path()); }
  ~EurocImportHarness() { std::filesystem::remove_all(dir_); }

  // Imports `imu_csv` as mav0/imu0/data.csv with `reference`: written where EuRoC keeps its ground truth
  // (the import's default) for ReferenceFormat::euroc_gt, or given as --reference for ReferenceFormat::tum.
  void import(std::string_view imu_csv, std::optional<std::string_view> reference, importers::ReferenceFormat format) {
    write(imu_csv_, imu_csv);
    importers::EurocImportOptions options{.dir = dir_};
    std::filesystem::remove(ground_truth_);
    if (reference && format == importers::ReferenceFormat::euroc_gt) {
      std::filesystem::create_directories(ground_truth_.parent_path());
      write(ground_truth_, *reference);
    } else if (reference) {
      write(tum_, *reference);
      options.reference = importers::ReferenceFile{tum_, format};
    }
    // A fresh store each time: one that persisted would grow, and every input that leaves memory allocated sends
    // libFuzzer through a leak check, which takes a hundred times longer than the import.
    std::filesystem::remove(db_);
    std::filesystem::remove(db_.string() + "-wal");
    std::filesystem::remove(db_.string() + "-shm");
    store::Store store(db_);
    try {
      importers::import_euroc(store, options);
    } catch (const std::invalid_argument&) {
    } catch (const store::StoreError&) {
    }
  }

 private:
  static void write(const std::filesystem::path& path, std::string_view text) {
    std::ofstream(path, std::ios::binary | std::ios::trunc)
        .write(text.data(), static_cast<std::streamsize>(text.size()));
  }

  // In memory where there is a tmpfs: SQLite syncs the store to disk at every commit.
  std::filesystem::path dir_ = (std::filesystem::is_directory("/dev/shm") ? std::filesystem::path("/dev/shm")
                                                                          : std::filesystem::temp_directory_path()) /
                               ("imubridge_fuzz_import_" + std::to_string(::getpid()));
  std::filesystem::path imu_csv_ = dir_ / "mav0" / "imu0" / "data.csv";
  std::filesystem::path ground_truth_ = dir_ / "mav0" / "state_groundtruth_estimate0" / "data.csv";
  std::filesystem::path tum_ = dir_ / "reference_tum.txt";
  std::filesystem::path db_ = dir_ / "import.db";
};

}  // namespace imubridge::fuzz
