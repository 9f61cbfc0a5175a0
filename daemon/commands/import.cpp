// `imubridge import euroc`: an EuRoC/ASL dataset into a new session, from bytes like a recorded flight, with its
// reference trajectory. docs/replay.md.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <string>

#include "daemon/command.hpp"
#include "daemon/config.hpp"
#include "replay/euroc_import.hpp"

namespace imubridge::cli {
namespace {

struct ImportCommandOptions {
  std::string format, dir, reference, reference_format = "tum";
  std::string db = daemon::StoreConfig{}.path.string();
  double accel_lsb = replay::EurocImportOptions{}.accel_lsb;
  double gyro_lsb = replay::EurocImportOptions{}.gyro_lsb;
  std::string imu_axes = "auto";
};

void print_lines(const char* what, const replay::ImportedFile& file, const replay::LinesByReason& lines) {
  if (lines.count() == 0) return;
  std::fprintf(stderr, "%s %llu %s of %s:\n", what, static_cast<unsigned long long>(lines.count()),
               lines.count() == 1 ? "row" : "rows", file.path.c_str());
  for (const auto& line : lines.summary()) std::fprintf(stderr, "  %s\n", line.c_str());
}

int run_import(const ImportCommandOptions& o) {
  replay::EurocImportOptions options{
      .dir = o.dir, .accel_lsb = o.accel_lsb, .gyro_lsb = o.gyro_lsb, .imu_axes = o.imu_axes};
  if (!o.reference.empty()) options.reference = {o.reference, replay::parse_reference_format(o.reference_format)};
  store::Store store(o.db);
  const auto r = replay::import_euroc(store, options);
  std::fprintf(stderr, "imported %llu IMU rows of %s into %s as session %lld\n",
               static_cast<unsigned long long>(r.imu.rows), r.imu.path.c_str(), o.db.c_str(),
               static_cast<long long>(r.session));
  std::fprintf(stderr, "%s\n", r.axes.description.c_str());
  if (r.axes.mismatch) std::fprintf(stderr, "warning: %s\n", r.axes.mismatch->c_str());
  if (r.axes.note) std::fprintf(stderr, "note: %s\n", r.axes.note->c_str());
  print_lines("skipped", r.imu, r.imu.skipped);
  print_lines("warning: clipped values in", r.imu, r.clipped);
  if (r.reference) {
    std::fprintf(stderr, "reference: %llu rows of %s%s\n", static_cast<unsigned long long>(r.reference->rows),
                 r.reference->path.c_str(),
                 r.velocity_derived ? ", velocity derived from the positions (quadratic fit over +-0.1 s)" : "");
    print_lines("skipped", *r.reference, r.reference->skipped);
  } else {
    std::fprintf(stderr, "no reference trajectory (give one with --reference)\n");
  }
  std::printf("%lld\n", static_cast<long long>(r.session));
  return 0;
}

const RegisterCommand kImport([](CLI::App& app) -> CommandRunner {
  auto o = std::make_shared<ImportCommandOptions>();
  auto* cmd = app.add_subcommand("import", "Import a dataset as a new session (prints its id last)");
  cmd->add_option("format", o->format, "Dataset format")->check(CLI::IsMember({"euroc"}))->required();
  cmd->add_option("dir", o->dir, "The dataset's directory (the one holding mav0/)")->required();
  auto* reference = cmd->add_option("--reference", o->reference,
                                    "Reference trajectory (default: mav0/state_groundtruth_estimate0/data.csv)");
  cmd->add_option("--reference-format", o->reference_format, "Format of --reference")
      ->check(CLI::IsMember({"tum", "euroc-gt"}))
      ->needs(reference)
      ->capture_default_str();
  cmd->add_option("--db", o->db, "The session store to import into")->capture_default_str();
  cmd->add_option("--imu-axes", o->imu_axes,
                  "The IMU's axes, recorded with the session: auto (from gravity), frd, flu, x-up (EuRoC's "
                  "ADIS16448), R:r00,...,r22 or q:w,x,y,z (IMU -> body; docs/estimator.md, IMU axes)")
      ->capture_default_str();
  cmd->add_option("--accel-lsb", o->accel_lsb, "Accelerometer resolution of the imported frames, m/s^2 per count")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--gyro-lsb", o->gyro_lsb, "Gyro resolution of the imported frames, rad/s per count")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->footer(
      "Rows that cannot be used are skipped and reported by line and reason; values beyond the frames'\n"
      "range are clipped and reported. tum: 't x y z qx qy qz qw', t in s; euroc-gt: EuRoC's ground-truth CSV.");
  return [o] { return run_import(*o); };
});

}  // namespace
}  // namespace imubridge::cli
