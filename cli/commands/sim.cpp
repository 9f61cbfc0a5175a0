// `imubridge sim`: fly a simulated quadrotor and deliver its IMU stream — recorded as a session, written as an
// EuRoC/ASL dataset, a capture file or a MAVLink telemetry log, or streamed live on a pseudo-terminal.
#include <CLI/CLI.hpp>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "cli/command.hpp"
#include "cli/new_store.hpp"
#include "cli/pty.hpp"
#include "estimator/imu_axes.hpp"
#include "fileio/whole_file.hpp"
#include "pipeline/link_recorder.hpp"
#include "pipeline/recorded_session.hpp"
#include "pipeline/session_config.hpp"
#include "pipeline/session_engine.hpp"
#include "protocol/calibration.hpp"
#include "importers/tlog.hpp"
#include "sim/frame_encoder.hpp"
#include "sim/scenario.hpp"
#include "store/store.hpp"

namespace imubridge::cli {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

struct SimOptions {
  std::string scenario = "paper";
  std::uint64_t seed = 1;
  std::optional<double> duration_s;
  std::optional<double> rate_hz;
  std::vector<std::string> effects;
  std::string protocol = "imubridge";
  double speed = 1.0;
  std::string db, euroc, pty, file, tlog;
  std::string imu_axes = "frd";
};

// --pty's pace. Beyond these it stops meaning anything: at 0.001 a 200 Hz IMU already sends one sample every 5 s,
// and at 1000 the longest flight streams in 90 s.
constexpr double kMinSpeed = 0.001, kMaxSpeed = 1000.0;
// IMU rates a ground station meets span 100 to 1000 Hz; beyond 10 kHz a day's flight would be a billion samples.
constexpr double kMinRateHz = 1.0, kMaxRateHz = 10000.0;

std::string format_number(double value) {
  std::ostringstream text;
  text << value;
  return text.str();
}

// An option's value outside [min, max], named in one line: "--rate 1e+09: must be from 1 to 10000 Hz".
void require_within(const char* option, double value, double min, double max, const char* unit) {
  if (!(value >= min && value <= max)) {
    throw std::invalid_argument(std::string(option) + " " + format_number(value) + ": must be from " +
                                format_number(min) + " to " + format_number(max) + " " + unit);
  }
}

volatile std::sig_atomic_t g_stop = 0;
extern "C" void on_stop_signal(int) { g_stop = 1; }

std::int64_t wall_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}
std::int64_t to_ns(double seconds) { return std::llround(seconds * 1e9); }

sim::SimConfig make_config(const SimOptions& o) {
  sim::SimConfig config = sim::make_scenario(o.scenario, o.seed, o.duration_s, o.effects);
  if (o.rate_hz) config.imu.rate_hz = *o.rate_hz;
  return config;
}

// The IMU mounted in other axes: each reading's vectors turned by R_bs^T (v_imu = R_bs^T v_body), then quantised
// again, so what the frames carry is what such a sensor would send. The signed-axis conventions land exactly on the
// count grid of a symmetric calibration. frd leaves the sample untouched.
struct AxesWriter {
  estimator::ImuAxes axes;
  const protocol::Calibration& calibration;

  sim::SimSample operator()(const sim::SimSample& in) const {
    if (estimator::is_identity(axes)) return in;
    const Eigen::Matrix3d r = axes.imu_to_body.transpose();
    sim::SimSample s = in;
    const auto array_of = [](const Eigen::Vector3d& v) { return std::array{v.x(), v.y(), v.z()}; };
    for (sim::ImuReading* m : {&s.ideal, &s.measured}) {
      m->accel = r * m->accel;
      m->gyro = r * m->gyro;
      m->mag = r * m->mag;
    }
    s.raw = calibration.to_counts(array_of(s.measured.accel), array_of(s.measured.gyro), array_of(s.measured.mag),
                                  s.measured.temperature_c);
    const protocol::Sample decoded = calibration.to_sample(s.raw);
    const auto vector_of = [](const std::array<double, 3>& a) { return Eigen::Vector3d(a[0], a[1], a[2]); };
    s.measured = {vector_of(decoded.accel), vector_of(decoded.gyro), vector_of(decoded.mag), decoded.temperature_c};
    return s;
  }
};

nlohmann::json describe(const SimOptions& o, const sim::SimConfig& config) {
  return {{"scenario", o.scenario},        {"seed", o.seed},       {"duration_s", config.duration_s},
          {"rate_hz", config.imu.rate_hz}, {"effects", o.effects}, {"protocol", o.protocol}};
}

// The reference_* effects model a receiver's reference, which only a recorded session (--db) carries as such.
void refuse_reference_effects(const sim::SimConfig& config, const char* output) {
  if (!config.reference.is_truth())
    throw std::invalid_argument(std::string("the reference_delay, reference_rate and reference_quantum effects apply "
                                            "to --db only, not ") +
                                output);
}

// The flight as a session: the bytes a ground station would have received, through the session engine and the
// recorder the daemon uses, with the simulator's truth as the session's reference trajectory. The engine has no
// estimation stage: sim has no parameters (a replay of the session estimates).
int record_to_db(const SimOptions& o, const sim::SimConfig& config) {
  const auto format = protocol::parse_wire_format(o.protocol);
  const daemon::NewStoreGuard new_store(o.db);
  store::Store store(o.db);
  const std::int64_t start_wall = wall_now_ns();
  const AxesWriter in_axes{estimator::parse_imu_axes(o.imu_axes), config.imu.calibration};
  const std::vector<pipeline::SessionLink> links{{.recorded = {"sim", format, config.imu.calibration, o.imu_axes},
                                                  .device = "simulated IMU, scenario " + o.scenario}};
  const pipeline::RecordedSession recorded =
      pipeline::begin_recorded_session(store,
                                       {.kind = "sim",
                                        .source = "imubridge sim " + describe(o, config).dump(),
                                        .config = describe(o, config),
                                        .started_wall_ns = start_wall},
                                       links);
  const std::int64_t session = recorded.id;
  pipeline::SessionEngine engine(nullptr);
  engine.add_link(pipeline::make_decoder(links[0].recorded));
  pipeline::SessionRecording recording(store, recorded, links, engine);
  engine.add_sink(recording);
  sim::FrameEncoder encoder(format);
  std::vector<std::uint8_t> bytes;
  std::int64_t last_ns = 0;
  sim::ReferenceReceiver receiver(config.reference);
  sim::simulate(config, [&](const sim::SimSample& s) {
    last_ns = to_ns(s.time_s);
    bytes.clear();
    encoder.encode(in_axes(s), bytes);
    if (!bytes.empty()) engine.on_chunk(0, bytes, last_ns, start_wall + last_ns);
    if (const std::optional<sim::ReferencePose> pose = receiver.next(s.truth)) {
      const auto& q = pose->attitude;
      const auto& p = pose->position_ned;
      const auto& v = pose->velocity_ned;
      store.append_reference(session, {.t_ns = to_ns(pose->t),
                                       .position = {p.x(), p.y(), p.z()},
                                       .quat_wxyz = {q.w(), q.x(), q.y(), q.z()},
                                       .velocity = std::array{v.x(), v.y(), v.z()}});
    }
    store.commit_if_due(Clock::now());
  });
  bytes.clear();
  encoder.flush(bytes);
  if (!bytes.empty()) engine.on_chunk(0, bytes, last_ns, start_wall + last_ns);
  engine.finish_link(0, last_ns, start_wall + last_ns);
  engine.finish();
  pipeline::end_recorded_session(store, session, wall_now_ns());
  std::fprintf(stderr, "recorded %s flight (%.1f s, seed %llu) into %s as session %lld\n", o.scenario.c_str(),
               config.duration_s, static_cast<unsigned long long>(o.seed), o.db.c_str(),
               static_cast<long long>(session));
  std::printf("%lld\n", static_cast<long long>(session));
  return 0;
}

// EuRoC/ASL layout. EuRoC's world frame has z up and its poses are the sensor's: so positions and velocities are
// the IMU's (not the mass centre's), rotated from NED by 180 degrees about x, and q_RS takes sensor axes to world.
int write_euroc(const SimOptions& o, const sim::SimConfig& config) {
  refuse_reference_effects(config, "--euroc");
  const fs::path root = fs::path(o.euroc) / "mav0";
  fs::create_directories(root / "imu0");
  fs::create_directories(root / "state_groundtruth_estimate0");
  fileio::WholeFile imu_file(root / "imu0" / "data.csv");
  fileio::WholeFile truth_file(root / "state_groundtruth_estimate0" / "data.csv");
  std::ostream& imu = imu_file.stream();
  std::ostream& truth = truth_file.stream();
  imu << "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
         "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n";
  truth << "#timestamp,p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z [],"
           "v_RS_R_x [m s^-1],v_RS_R_y [m s^-1],v_RS_R_z [m s^-1],b_w_RS_S_x [rad s^-1],b_w_RS_S_y [rad s^-1],"
           "b_w_RS_S_z [rad s^-1],b_a_RS_S_x [m s^-2],b_a_RS_S_y [m s^-2],b_a_RS_S_z [m s^-2]\n";
  imu.precision(17);
  truth.precision(17);
  const Eigen::Matrix3d zup_from_ned = Eigen::Vector3d(1, -1, -1).asDiagonal();
  const AxesWriter in_axes{estimator::parse_imu_axes(o.imu_axes), config.imu.calibration};
  // The sensor's axes are the mounted ones turned by R_bs^T: sensor -> body takes R_bs first.
  const Eigen::Matrix3d body_from_sensor =
      estimator::is_identity(in_axes.axes)
          ? Eigen::Matrix3d(config.imu.pose.sensor_from_body.transpose())
          : Eigen::Matrix3d(config.imu.pose.sensor_from_body.transpose() * in_axes.axes.imu_to_body);
  const Eigen::Vector3d& r = config.imu.pose.position_m;
  const auto& errors = config.imu.errors;
  const std::int64_t t0 = 1'000'000'000'000'000'000;  // an EuRoC-like epoch stamp, fixed so files are reproducible
  std::uint64_t n = 0;
  sim::simulate(config, [&](const sim::SimSample& sample) {
    const sim::SimSample s = in_axes(sample);
    const std::int64_t t = t0 + to_ns(s.time_s);
    const auto& m = s.measured;
    imu << t << ',' << m.gyro.x() << ',' << m.gyro.y() << ',' << m.gyro.z() << ',' << m.accel.x() << ',' << m.accel.y()
        << ',' << m.accel.z() << '\n';
    const Eigen::Matrix3d ned_from_body = s.truth.attitude.toRotationMatrix();
    const Eigen::Vector3d p = zup_from_ned * (s.truth.position_ned + ned_from_body * r);
    const Eigen::Vector3d v = zup_from_ned * (s.truth.velocity_ned + ned_from_body * s.truth.omega.cross(r));
    const Eigen::Quaterniond q(zup_from_ned * ned_from_body * body_from_sensor);
    truth << t << ',' << p.x() << ',' << p.y() << ',' << p.z() << ',' << q.w() << ',' << q.x() << ',' << q.y() << ','
          << q.z() << ',' << v.x() << ',' << v.y() << ',' << v.z() << ',' << errors.gyro_bias.x() << ','
          << errors.gyro_bias.y() << ',' << errors.gyro_bias.z() << ',' << errors.accel_bias.x() << ','
          << errors.accel_bias.y() << ',' << errors.accel_bias.z() << '\n';
    ++n;
  });
  imu_file.commit();
  truth_file.commit();
  std::fprintf(stderr, "wrote %llu samples in EuRoC/ASL layout under %s\n", static_cast<unsigned long long>(n),
               o.euroc.c_str());
  return 0;
}

// The wire bytes, either into a file as fast as possible, or onto a pseudo-terminal at the flight's own pace.
int stream_bytes(const SimOptions& o, const sim::SimConfig& config) {
  refuse_reference_effects(config, o.pty.empty() ? "--file" : "--pty");
  const auto format = protocol::parse_wire_format(o.protocol);
  sim::FrameEncoder encoder(format);
  std::vector<std::uint8_t> bytes;
  std::unique_ptr<PtyPair> pty;
  std::optional<fileio::WholeFile> file;
  if (!o.pty.empty()) {
    pty = std::make_unique<PtyPair>(o.pty);
    std::fprintf(stderr, "streaming %s frames on %s (%s) at %gx real time; Ctrl-C stops\n", o.protocol.c_str(),
                 o.pty.c_str(), pty->slave_name().c_str(), o.speed);
    std::signal(SIGINT, on_stop_signal);
    std::signal(SIGTERM, on_stop_signal);
  } else {
    file.emplace(o.file);
  }
  const auto start = Clock::now();
  std::uint64_t written = 0;
  auto deliver = [&](double t) {
    if (bytes.empty()) return;
    if (pty) {
      std::this_thread::sleep_until(start + std::chrono::nanoseconds(to_ns(t / o.speed)));
      pty->write(bytes);
    } else {
      file->stream().write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    }
    written += bytes.size();
    bytes.clear();
  };
  const AxesWriter in_axes{estimator::parse_imu_axes(o.imu_axes), config.imu.calibration};
  sim::Simulator simulator(config);
  double t = 0;
  while (!g_stop) {
    auto s = simulator.next();
    if (!s) break;
    t = s->time_s;
    encoder.encode(in_axes(*s), bytes);
    deliver(t);
  }
  encoder.flush(bytes);
  deliver(t);
  if (file) file->commit();
  const std::size_t unread = pty ? pty->drain() : 0;  // closing the pty would discard what its reader has not read
  std::fprintf(stderr, "sent %llu bytes (%.1f s of flight)", static_cast<unsigned long long>(written), t);
  if (pty && pty->dropped_bytes() + unread > 0) {
    std::fprintf(stderr, "; nobody was reading: %llu bytes dropped, at least %llu left unread",
                 static_cast<unsigned long long>(pty->dropped_bytes()), static_cast<unsigned long long>(unread));
  }
  std::fprintf(stderr, "\n");
  return 0;
}

// The flight as a ground station's MAVLink telemetry log (.tlog): every frame of sim::MavlinkTelemetry (HIGHRES_IMU,
// with ATTITUDE and LOCAL_POSITION_NED of the truth) a record stamped with a fixed epoch plus the flight's time, so a
// seed always writes the same file and `import tlog` finds the simulator's samples and trajectory in it.
int write_tlog(const SimOptions& o, const sim::SimConfig& config) {
  refuse_reference_effects(config, "--tlog");
  if (o.protocol != "mavlink") throw std::invalid_argument("--tlog writes MAVLink telemetry: give --protocol mavlink");
  constexpr std::uint64_t kEpochUs = 1'704'067'200'000'000;  // 2024-01-01 00:00:00 UTC
  fileio::WholeFile file(o.tlog);
  const AxesWriter in_axes{estimator::parse_imu_axes(o.imu_axes), config.imu.calibration};
  sim::MavlinkTelemetry telemetry;
  std::vector<std::vector<std::uint8_t>> frames;
  std::vector<std::uint8_t> bytes;
  std::uint64_t records = 0;
  sim::simulate(config, [&](const sim::SimSample& s) {
    frames.clear();
    bytes.clear();
    telemetry.encode(in_axes(s), frames);
    const auto t = kEpochUs + static_cast<std::uint64_t>(std::llround(s.time_s * 1e6));
    for (const auto& frame : frames) importers::tlog::append_record(bytes, t, frame);
    file.stream().write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    records += frames.size();
  });
  file.commit();
  std::fprintf(stderr, "wrote %llu MAVLink records (%.1f s of flight) into %s\n",
               static_cast<unsigned long long>(records), config.duration_s, o.tlog.c_str());
  return 0;
}

const RegisterCommand kSim([](CLI::App& app) -> CommandRunner {
  auto o = std::make_shared<SimOptions>();
  auto* cmd = app.add_subcommand("sim", "Fly a simulated quadrotor and record, write or stream its IMU data");
  std::string scenarios;  // from the simulator's own list, so a new scenario is never missing here
  for (const std::string_view name : sim::scenario_names()) {
    scenarios += (scenarios.empty() ? "" : " | ") + std::string(name);
  }
  cmd->add_option("--scenario", o->scenario, scenarios + " (docs/simulator.md)")->capture_default_str();
  cmd->add_option("--seed", o->seed, "Random seed: same seed, same bytes")->capture_default_str();
  cmd->add_option(
      "--duration", o->duration_s,
      "Flight length in seconds, at most " + format_number(sim::kMaxDurationS) + " (24 h) (default: the scenario's)");
  cmd->add_option("--rate", o->rate_hz,
                  "IMU sample rate in Hz, from " + format_number(kMinRateHz) + " to " + format_number(kMaxRateHz) +
                      " (default: the scenario's)");
  cmd->add_option("--effect", o->effects, "Extra effect NAME=VALUE, repeatable (docs/simulator.md lists them)");
  cmd->add_option("--protocol", o->protocol, "Wire format for --db, --pty and --file; --tlog needs mavlink")
      ->check(CLI::IsMember({"imubridge", "xbee", "xbee-escaped", "mavlink"}))
      ->capture_default_str();
  cmd->add_option("--speed", o->speed,
                  "Pace for --pty, as a multiple of real time, from " + format_number(kMinSpeed) + " to " +
                      format_number(kMaxSpeed))
      ->capture_default_str();
  cmd->add_option("--imu-axes", o->imu_axes,
                  "The IMU's axes in the samples: frd, flu, x-up, x-down, y-up, y-down, R:r00,...,r22 or q:w,x,y,z "
                  "(IMU -> body); the reference stays the body's (docs/estimator.md, IMU axes)")
      ->check([](const std::string& text) {
        try {
          if (estimator::parse_imu_axes(text).automatic) return std::string("a simulated IMU has definite axes");
          return std::string();
        } catch (const std::invalid_argument& e) {
          return std::string(e.what());
        }
      })
      ->capture_default_str();
  auto* out = cmd->add_option_group("output", "Where the flight goes (exactly one)");
  out->add_option("--db", o->db, "Record into this SQLite store as a new session (prints its id last)");
  out->add_option("--euroc", o->euroc, "Write an EuRoC/ASL dataset (mav0/imu0, mav0/state_groundtruth_estimate0)");
  out->add_option("--pty", o->pty, "Create a pseudo-terminal, link it at this path, and stream in real time");
  out->add_option("--file", o->file, "Write the wire bytes to this file");
  out->add_option("--tlog", o->tlog,
                  "Write a MAVLink telemetry log (.tlog; with --protocol mavlink): HIGHRES_IMU, ATTITUDE and "
                  "LOCAL_POSITION_NED, stamped from 2024-01-01 00:00 UTC");
  out->require_option(1);
  return [o] {
    if (o->rate_hz) require_within("--rate", *o->rate_hz, kMinRateHz, kMaxRateHz, "Hz");
    require_within("--speed", o->speed, kMinSpeed, kMaxSpeed, "times real time");
    const sim::SimConfig config = make_config(*o);
    if (!o->db.empty()) return record_to_db(*o, config);
    if (!o->euroc.empty()) return write_euroc(*o, config);
    if (!o->tlog.empty()) return write_tlog(*o, config);
    return stream_bytes(*o, config);
  };
});

}  // namespace
}  // namespace imubridge::cli
