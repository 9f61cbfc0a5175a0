// `imubridge import euroc|ulog|tlog|dataflash`: an EuRoC/ASL dataset, a PX4 ULog file, a MAVLink telemetry log or an
// ArduPilot DataFlash log into a new session, from bytes like a recorded flight, with its reference trajectory.
// docs/replay.md.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <map>
#include <string>

#include "cli/command.hpp"
#include "cli/import_progress_line.hpp"
#include "cli/new_store.hpp"
#include "daemon/config.hpp"
#include "importers/dataflash_import.hpp"
#include "importers/euroc_import.hpp"
#include "importers/tlog_import.hpp"
#include "importers/ulog_import.hpp"

namespace imubridge::cli {
namespace {

struct ImportCommandOptions {
  std::string format, dir, reference, reference_format = "tum";
  std::string db = daemon::StoreConfig{}.path.string();
  double accel_lsb = importers::EurocImportOptions{}.accel_lsb;
  double gyro_lsb = importers::EurocImportOptions{}.gyro_lsb;
  std::string imu_axes = "auto";
  std::string imu_message;
  bool no_reference = false;
  int imu = -1;  // dataflash: the IMU instance; -1: the default
  double gap_threshold_s = importers::kDefaultGapThresholdS;
  // Whether the user gave these: ulog has its own defaults for what was not given.
  bool imu_axes_given = false, accel_lsb_given = false, gyro_lsb_given = false;
};

// The problems an import reports, printed once, after its summary, the same way for every format: a line each, a
// warning where values were clipped or the file is damaged. Problems alike but for their place (a tlog's damaged
// stretches) are one line with their counts summed and the first's place.
class ProblemLines {
 public:
  importers::ProblemCallback callback() {
    return [this](const importers::ImportProblem& p) { add(p); };
  }
  void print() const {
    for (const auto& [problem, places] : merged_) {
      importers::ImportProblem shown = problem;
      if (places > 1 && shown.where) *shown.where += "; the first of " + std::to_string(places);
      std::fprintf(stderr, "%s%s\n", problem.kind == importers::ProblemKind::skipped ? "" : "warning: ",
                   importers::describe(shown).c_str());
    }
  }

 private:
  void add(const importers::ImportProblem& p) {
    const auto alike = std::ranges::find_if(merged_, [&](const Merged& m) {
      return m.problem.kind == p.kind && m.problem.what == p.what && m.problem.why == p.why;
    });
    if (alike == merged_.end()) {
      merged_.push_back({p});
    } else {
      alike->problem.count += p.count;
      ++alike->places;
    }
  }
  struct Merged {
    importers::ImportProblem problem;
    std::uint64_t places = 1;
  };
  std::vector<Merged> merged_;
};

// Runs `import` into the store, showing how far it is on a terminal and collecting its problems.
template <typename ImportOptions, typename Import>
auto import_with_progress(const ImportCommandOptions& o, ImportOptions& options, Import import,
                          ProblemLines& problems) {
  const daemon::NewStoreGuard new_store(o.db);  // no empty store left behind by a failed import
  store::Store store(o.db);
  ImportProgressLine progress(o.dir);
  options.progress = progress.callback();
  options.on_problem = problems.callback();
  auto r = import(store, options);
  progress.finish();
  return r;
}

// What ulog, tlog and dataflash take of the shared options: the resolutions and axes only where given, else their own
// defaults.
template <typename ImportOptions>
void apply_given(const ImportCommandOptions& o, ImportOptions& options) {
  if (o.accel_lsb_given) options.accel_lsb = o.accel_lsb;
  if (o.gyro_lsb_given) options.gyro_lsb = o.gyro_lsb;
  if (o.imu_axes_given) options.imu_axes = o.imu_axes;
}

// The first line of a log's import (ulog, tlog): what became the session.
template <typename ImportResult>
void print_imported_log(const ImportCommandOptions& o, const ImportResult& r) {
  std::fprintf(stderr, "imported %llu IMU samples (%s, %.1f s) of %s into %s as session %lld\n",
               static_cast<unsigned long long>(r.samples), r.imu_source.c_str(),
               static_cast<double>(r.last_us - r.first_us) * 1e-6, o.dir.c_str(), o.db.c_str(),
               static_cast<long long>(r.session));
}

void print_axes(const estimator::AxesResolution& axes) {
  std::fprintf(stderr, "%s\n", axes.description.c_str());
  if (axes.mismatch) std::fprintf(stderr, "warning: %s\n", axes.mismatch->c_str());
  if (axes.note) std::fprintf(stderr, "note: %s\n", axes.note->c_str());
}

// The first lines of an on-board log's import (ulog, dataflash): the session and the axes.
void print_imu_log(const ImportCommandOptions& o, const importers::ImuLogImportResult& r) {
  print_imported_log(o, r);
  print_axes(r.axes);
}

// The holes in the IMU's data, every import's: how many, how long, the longest's span.
void print_gaps(const importers::Gaps& gaps) {
  if (gaps.holes.empty()) {
    std::fprintf(stderr, "gaps: none (the IMU never stops for over %g s)\n", gaps.threshold_s);
    return;
  }
  const auto longest = std::ranges::max_element(gaps.holes, {}, &importers::Gap::seconds);
  std::fprintf(stderr,
               "warning: %zu %s without IMU samples over %g s (%.1f s in all; the longest %.1f s, %.1f-%.1f s)\n",
               gaps.holes.size(), gaps.holes.size() == 1 ? "gap" : "gaps", gaps.threshold_s, gaps.seconds(),
               longest->seconds(), static_cast<double>(longest->from_ns - gaps.session_start_ns) * 1e-9,
               static_cast<double>(longest->to_ns - gaps.session_start_ns) * 1e-9);
}

// The last lines of every import: the holes, the problems, the session's id alone on stdout.
void print_end(const importers::Gaps& gaps, const ProblemLines& problems, std::int64_t session) {
  print_gaps(gaps);
  problems.print();
  std::printf("%lld\n", static_cast<long long>(session));
}

void print_reference(const ImportCommandOptions& o, std::uint64_t rows, const std::string& source, const char* none) {
  if (o.no_reference) {
    std::fprintf(stderr, "no reference trajectory (--no-reference)\n");
  } else if (rows == 0) {
    std::fprintf(stderr, "no reference trajectory (the log has no usable %s)\n", none);
  } else {
    std::fprintf(stderr, "reference: %llu rows (%s)\n", static_cast<unsigned long long>(rows), source.c_str());
  }
}

// When the vehicle flew, by PX4's land detector, in seconds from the first sample.
void print_airborne(const importers::UlogImportResult& r) {
  if (!r.airborne) {
    std::fprintf(stderr, "airborne: unknown (no vehicle_land_detected record in the log)\n");
    return;
  }
  if (r.airborne->empty()) {
    std::fprintf(stderr, "airborne: never (vehicle_land_detected says landed throughout)\n");
    return;
  }
  double total_s = 0;
  std::string intervals;
  for (const auto& flight : *r.airborne) {
    const double from_s = (static_cast<double>(flight.from_us) - static_cast<double>(r.first_us)) * 1e-6;
    const double to_s = (static_cast<double>(flight.to_us) - static_cast<double>(r.first_us)) * 1e-6;
    total_s += to_s - from_s;
    char text[64];
    std::snprintf(text, sizeof text, "%s%.1f-%.1f s", intervals.empty() ? "" : ", ", from_s, to_s);
    intervals += text;
  }
  std::fprintf(stderr, "airborne: %.1f s (vehicle_land_detected; from the first sample: %s)\n", total_s,
               intervals.c_str());
}

int run_import_ulog(const ImportCommandOptions& o) {
  if (!o.reference.empty()) throw std::invalid_argument("--reference is for euroc: a ULog file holds its own");
  if (!o.imu_message.empty()) throw std::invalid_argument("--imu-message is for tlog");
  if (o.imu >= 0) throw std::invalid_argument("--imu is for dataflash");
  importers::UlogImportOptions options{
      .file = o.dir, .reference = !o.no_reference, .gap_threshold_s = o.gap_threshold_s};
  apply_given(o, options);
  ProblemLines problems;
  const auto r = import_with_progress(o, options, importers::import_ulog, problems);
  print_imu_log(o, r);
  print_reference(o, r.reference_rows, "vehicle_local_position, attitude from vehicle_attitude",
                  "vehicle_attitude + vehicle_local_position");
  print_airborne(r);
  std::fprintf(
      stderr, "events: %llu logged strings, %llu dropouts (%llu ms)%s\n", static_cast<unsigned long long>(r.log_events),
      static_cast<unsigned long long>(r.dropouts), static_cast<unsigned long long>(r.dropout_ms),
      r.data_appended ? (", appended data: " + std::to_string(r.appended_messages) + " messages").c_str() : "");
  print_end(r.gaps, problems, r.session);
  return 0;
}

int run_import_dataflash(const ImportCommandOptions& o) {
  if (!o.reference.empty()) throw std::invalid_argument("--reference is for euroc: a DataFlash log holds its own");
  if (!o.imu_message.empty()) throw std::invalid_argument("--imu-message is for tlog");
  importers::DataflashImportOptions options{
      .file = o.dir, .reference = !o.no_reference, .gap_threshold_s = o.gap_threshold_s};
  apply_given(o, options);
  if (o.imu >= 0) options.imu = static_cast<unsigned>(o.imu);
  ProblemLines problems;
  const auto r = import_with_progress(o, options, importers::import_dataflash, problems);
  print_imu_log(o, r);
  std::string imus;
  for (const auto& [i, text] : r.imus) imus += (imus.empty() ? "" : "; ") + std::to_string(i) + ": " + text;
  std::fprintf(stderr, "IMU instance %u imported (--imu N picks another); the log's: %s\n", r.instance, imus.c_str());
  print_reference(o, r.reference_rows, r.reference_source, "EKF1, NKF1 or XKF1 (with ATT)");
  std::fprintf(stderr,
               "events: %llu MSG, %llu MODE changes, %llu arming changes, %llu land detector changes (takeoff, "
               "landing); %llu parameters in the config\n",
               static_cast<unsigned long long>(r.log_events), static_cast<unsigned long long>(r.mode_changes),
               static_cast<unsigned long long>(r.arming_changes),
               static_cast<unsigned long long>(r.land_detector_changes), static_cast<unsigned long long>(r.params));
  print_end(r.gaps, problems, r.session);
  return 0;
}

int run_import_tlog(const ImportCommandOptions& o) {
  if (!o.reference.empty()) throw std::invalid_argument("--reference is for euroc: a tlog holds its own");
  if (o.imu >= 0) throw std::invalid_argument("--imu is for dataflash (tlog: --imu-message)");
  importers::TlogImportOptions options{
      .file = o.dir, .reference = !o.no_reference, .gap_threshold_s = o.gap_threshold_s};
  apply_given(o, options);
  if (!o.imu_message.empty()) options.imu_message = o.imu_message;
  ProblemLines problems;
  const auto r = import_with_progress(o, options, importers::import_tlog, problems);
  print_imported_log(o, r);
  std::fprintf(stderr, "%llu records, every frame kept as received%s\n", static_cast<unsigned long long>(r.records),
               r.unverified_summary
                   ? ("; valid frames nothing here can check, kept unchecked: " + *r.unverified_summary).c_str()
                   : "");
  print_axes(r.axes);
  print_reference(o, r.reference_rows, r.reference_source, "LOCAL_POSITION_NED with ATTITUDE_QUATERNION or ATTITUDE");
  std::fprintf(stderr, "events: %llu STATUSTEXT messages, %llu gaps in the log's time over %g s (%.1f s)%s\n",
               static_cast<unsigned long long>(r.log_events), static_cast<unsigned long long>(r.log_gaps),
               static_cast<double>(importers::kTlogGapUs) * 1e-6, r.log_gap_s,
               r.time_back > 0 ? (", its time stepped back " + std::to_string(r.time_back) + "x").c_str() : "");
  print_end(r.gaps, problems, r.session);
  return 0;
}

int run_import(const ImportCommandOptions& o) {
  if (o.format == "dataflash") return run_import_dataflash(o);
  if (o.format == "ulog") return run_import_ulog(o);
  if (o.format == "tlog") return run_import_tlog(o);
  if (o.no_reference) throw std::invalid_argument("--no-reference is for ulog, tlog and dataflash");
  if (!o.imu_message.empty()) throw std::invalid_argument("--imu-message is for tlog");
  if (o.imu >= 0) throw std::invalid_argument("--imu is for dataflash");
  importers::EurocImportOptions options{.dir = o.dir,
                                        .accel_lsb = o.accel_lsb,
                                        .gyro_lsb = o.gyro_lsb,
                                        .imu_axes = o.imu_axes,
                                        .gap_threshold_s = o.gap_threshold_s};
  if (!o.reference.empty()) options.reference = {o.reference, importers::parse_reference_format(o.reference_format)};
  ProblemLines problems;
  const auto r = import_with_progress(o, options, importers::import_euroc, problems);  // of its mav0/imu0/data.csv
  std::fprintf(stderr, "imported %llu IMU rows of %s into %s as session %lld\n",
               static_cast<unsigned long long>(r.imu.rows), r.imu.path.c_str(), o.db.c_str(),
               static_cast<long long>(r.session));
  print_axes(r.axes);
  if (r.reference) {
    std::fprintf(stderr, "reference: %llu rows of %s%s\n", static_cast<unsigned long long>(r.reference->rows),
                 r.reference->path.c_str(),
                 r.velocity_derived ? ", velocity derived from the positions (quadratic fit over +-0.1 s)" : "");
  } else {
    std::fprintf(stderr, "no reference trajectory (give one with --reference)\n");
  }
  print_end(r.gaps, problems, r.session);
  return 0;
}

const RegisterCommand kImport([](CLI::App& app) -> CommandRunner {
  auto o = std::make_shared<ImportCommandOptions>();
  auto* cmd = app.add_subcommand("import", "Import a dataset as a new session (prints its id last)");
  cmd->add_option("format", o->format, "Dataset format")
      ->check(CLI::IsMember({"euroc", "ulog", "tlog", "dataflash"}))
      ->required();
  cmd->add_option("dir", o->dir,
                  "euroc: the dataset's directory (the one holding mav0/); ulog: the .ulg file; tlog: the .tlog file; "
                  "dataflash: the .bin file")
      ->required();
  auto* reference = cmd->add_option("--reference", o->reference,
                                    "Reference trajectory (default: mav0/state_groundtruth_estimate0/data.csv)");
  cmd->add_option("--reference-format", o->reference_format, "Format of --reference")
      ->check(CLI::IsMember({"tum", "euroc-gt"}))
      ->needs(reference)
      ->capture_default_str();
  cmd->add_flag("--no-reference", o->no_reference,
                "ulog, tlog, dataflash: leave out the reference trajectory (vehicle_attitude + "
                "vehicle_local_position; LOCAL_POSITION_NED + ATTITUDE_QUATERNION or ATTITUDE; the EKF's)");
  cmd->add_option("--imu-message", o->imu_message,
                  "tlog: take the IMU from this message only (HIGHRES_IMU, SCALED_IMU, SCALED_IMU2, SCALED_IMU3, "
                  "RAW_IMU); default: the IMU that sends the most");
  cmd->add_option("--imu", o->imu,
                  "dataflash: the IMU instance to import (0: IMU, ACC1/GYR1 or I = 0; 1: IMU2, ...); default 0")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--gap-threshold", o->gap_threshold_s,
                  "Seconds without an IMU sample that make a hole in the data, reported and stored as a gap event")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--db", o->db, "The session store to import into")->capture_default_str();
  auto* imu_axes =
      cmd->add_option("--imu-axes", o->imu_axes,
                      "The IMU's axes, recorded with the session: auto (from gravity), frd, flu, x-up (EuRoC's "
                      "ADIS16448), R:r00,...,r22 or q:w,x,y,z (IMU -> body; docs/estimator.md, IMU axes); ulog, tlog, "
                      "dataflash: frd")
          ->capture_default_str();
  auto* accel_lsb =
      cmd->add_option("--accel-lsb", o->accel_lsb,
                      "Accelerometer resolution of the imported frames, m/s^2 per count (ulog: 5e-3; tlog: of "
                      "RAW_IMU, which is imported only given both resolutions, e.g. 0.00980665 for ArduPilot's mG)")
          ->check(CLI::PositiveNumber)
          ->capture_default_str();
  auto* gyro_lsb =
      cmd->add_option("--gyro-lsb", o->gyro_lsb,
                      "Gyro resolution of the imported frames, rad/s per count (ulog: 1.1e-3; tlog: of RAW_IMU, "
                      "e.g. 0.001 for ArduPilot's mrad/s)")
          ->check(CLI::PositiveNumber)
          ->capture_default_str();
  cmd->footer(
      "Rows that cannot be used are skipped and reported by line and reason; values beyond the frames'\n"
      "range are clipped and reported. tum: 't x y z qx qy qz qw', t in s; euroc-gt: EuRoC's ground-truth CSV.\n"
      "ulog: a PX4 log; IMU from sensor_combined (or sensor_accel + sensor_gyro), reference from vehicle_attitude\n"
      "and vehicle_local_position, logged strings and dropouts as events, parameters and info in the config.\n"
      "tlog: a MAVLink telemetry log (QGroundControl, Mission Planner, MAVProxy); every frame recorded as a\n"
      "mavlink link receives it, samples from the IMU sending the most messages, reference from\n"
      "LOCAL_POSITION_NED with ATTITUDE_QUATERNION (or ATTITUDE), STATUSTEXT, gaps and damage as events.\n"
      "dataflash: an ArduPilot .bin log; IMU from one instance's IMU (or ACC + GYR where faster; --imu N),\n"
      "reference from the EKF (XKF1, NKF1 or EKF1, with ATT), MSG, MODE and arming as events, PARM in the config.\n"
      "Every import reports the IMU stopping for over --gap-threshold seconds as a gap event.");
  return [o, imu_axes, accel_lsb, gyro_lsb] {
    o->imu_axes_given = imu_axes->count() > 0;
    o->accel_lsb_given = accel_lsb->count() > 0;
    o->gyro_lsb_given = gyro_lsb->count() > 0;
    return run_import(*o);
  };
});

}  // namespace
}  // namespace imubridge::cli
