#include "daemon/daemon.hpp"

#include <spdlog/pattern_formatter.h>
#include <spdlog/sinks/basic_file_sink.h>
#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <csignal>
#include <ctime>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>

#include "daemon/archive_sync.hpp"
#include "daemon/asio.hpp"
#include "daemon/bridge.hpp"
#include "daemon/config_file.hpp"
#include "daemon/daemon_internal.hpp"
#include "daemon/live_sinks.hpp"
#include "daemon/mavlink_requests.hpp"
#include "daemon/outputs.hpp"
#include "daemon/port_list.hpp"
#include "daemon/serial_link.hpp"
#include "daemon/vehicle_feedback.hpp"
#include "pipeline/estimation_stage.hpp"
#include "pipeline/radio_link.hpp"
#include "pipeline/session_engine.hpp"
#include "store/store.hpp"

namespace imubridge::daemon {
namespace {

// journald reads a leading "<N>" as the line's syslog priority.
class SyslogPriority : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& msg, const std::tm&, spdlog::memory_buf_t& dest) override {
    static constexpr std::string_view kPriority[] = {"<7>", "<7>", "<6>", "<4>", "<3>", "<2>", ""};
    const std::string_view p = kPriority[msg.level];
    dest.append(p.data(), p.data() + p.size());
  }
  std::unique_ptr<custom_flag_formatter> clone() const override { return std::make_unique<SyslogPriority>(); }
};

}  // namespace

void configure_logging(const Config& config) {
  spdlog::sink_ptr sink;
  if (config.log_file) {
    sink = std::make_shared<spdlog::sinks::basic_file_sink_mt>(config.log_file->string());
  } else {
    sink = std::make_shared<spdlog::sinks::stderr_sink_mt>();
  }
  auto formatter = std::make_unique<spdlog::pattern_formatter>();
  if (!config.log_file && stderr_is_journal()) {
    formatter->add_flag<SyslogPriority>('*').set_pattern("%*%v");
  } else {
    formatter->set_pattern("%Y-%m-%d %H:%M:%S.%e %l: %v");
  }
  sink->set_formatter(std::move(formatter));
  auto logger = std::make_shared<spdlog::logger>("imubridge", sink);
  logger->set_level(spdlog::level::from_str(config.log_level));
  logger->flush_on(spdlog::level::trace);  // lines are rare; each must reach the file before a crash could lose it
  spdlog::set_default_logger(std::move(logger));
}

// The daemon's own sink, first in line: each link's counts, a device restart said once, and, while recording,
// everything to the recording's sink. A store that fails ends the recording there (record()); the links, the
// estimates and the other sinks go on without it.
class Daemon::RecordingSink final : public pipeline::SessionSink {
 public:
  explicit RecordingSink(Daemon& daemon) : daemon_(daemon) {}
  void on_chunk(std::size_t index, const pipeline::DecodedChunk& chunk) override {
    daemon_.record([&](Recording& r) { r.sink->on_chunk(index, chunk); });
  }
  void on_sample(std::size_t index, const protocol::Sample& sample, std::span<const store::Estimate> estimates,
                 std::int64_t recv_mono_ns) override {
    Link& link = *daemon_.links_[index];
    ++link.samples;
    link.estimates += estimates.size();
    if (std::uint32_t& epoch = link.clock_epochs[sample.source]; sample.clock_epoch != epoch) {
      epoch = sample.clock_epoch;
      spdlog::warn(
          "link '{}': the device restarted (its sequence number and clock went back); estimating from its "
          "new clock",
          link.config.name);
    }
    daemon_.record([&](Recording& r) { r.sink->on_sample(index, sample, estimates, recv_mono_ns); });
  }
  void on_final_estimates(const protocol::SourceKey& source, std::span<const store::Estimate> estimates) override {
    daemon_.record([&](Recording& r) { r.sink->on_final_estimates(source, estimates); });
  }

 private:
  Daemon& daemon_;
};

Daemon::Daemon(Config config, std::optional<fs::path> config_file)
    : config_(std::move(config)),
      config_file_(std::move(config_file)),
      // A live flight is never the one PARAMS.json's conditions were fitted on: it flies the vehicle's calibration.
      params_(config_.params ? estimator::for_flight(estimator::load_params(*config_.params), "", &params_note_)
                             : estimator::ModelParams{}),
      signals_(io_, SIGINT, SIGTERM, SIGHUP),
      commit_timer_(io_),
      stats_timer_(io_),
      watchdog_timer_(io_),
      resume_timer_(io_) {
  signals_.add(SIGUSR1);
  if (!params_note_.empty()) spdlog::info("{}", params_note_);
  pipeline::StageAxes axes;
  for (std::size_t i = 0; i < config_.links.size(); ++i) {
    axes.links[static_cast<std::uint32_t>(i)] = estimator::parse_imu_axes(config_.links[i].axes);  // checked on load
  }
  axes.on_resolved = [this](const protocol::SourceKey& source, const estimator::AxesResolution& resolution) {
    on_axes_resolved(source, resolution);
  };
  // Bad parameters fail here, before any I/O.
  engine_ =
      std::make_unique<pipeline::SessionEngine>(std::make_unique<pipeline::EstimationStage>(params_, std::move(axes)));
  outputs_ = std::make_unique<Outputs>(io_, config_.outputs);
  for (const LinkConfig& link_config : config_.links) add_link(link_config);
  add_sinks();
  if (auto problem = storage_problem()) {
    spdlog::error("not recording: {}", *problem);
    not_recording_ = NotRecording{.path = config_.store.path, .previous = "", .reason = *problem};
  } else {
    open_recording(config_.store.path, "");  // a store that cannot be opened at start is fatal
  }
}

// Detection reports once per source: a declaration the data contradict is logged and recorded as an event (on the
// radio's store link for an XBee radio).
void Daemon::on_axes_resolved(const protocol::SourceKey& source, const estimator::AxesResolution& resolution) {
  const std::string& name = links_.at(source.link)->config.name;
  const std::string who = fmt::format("'{}'", source.radio ? pipeline::radio_link_name(name, *source.radio) : name);
  spdlog::info("link {}: {}", who, resolution.description);
  if (resolution.note) spdlog::info("link {}: {}", who, *resolution.note);
  if (!resolution.mismatch) return;
  spdlog::warn("link {}: {}", who, *resolution.mismatch);
  record([&](Recording& r) {
    r.store.append_event(r.session, {.link_id = r.sink->row(source),
                                     .mono_ns = mono_now_ns(),
                                     .wall_ns = wall_now_ns(),
                                     .kind = "imu_axes_mismatch",
                                     .detail = *resolution.mismatch});
  });
}

void Daemon::add_link(const LinkConfig& link_config) {
  auto link = std::make_unique<Link>();
  Link& l = *link;
  l.index = links_.size();
  l.config = link_config;
  // The link's one decoder for the whole run, whether recording or not.
  pipeline::LinkDecoder decoder(link_config.format, link_config.calibration);
  if (const auto lock = mavlink_imu_lock(link_config)) decoder.lock_mavlink_imu(*lock);
  engine_->add_link(std::move(decoder));
  l.port = std::make_unique<SerialLink>(
      io_, link_config,
      SerialLink::Handlers{
          .on_data = [this, &l](std::span<const std::uint8_t> bytes) { on_data(l, bytes); },
          .on_open = [this, &l](const std::string& path, bool reopened) { on_open(l, path, reopened); },
          .on_lost = [this, &l](const std::string& reason) { on_lost(l, reason); }});
  if (!link_config.bridge.empty()) {
    l.bridge = std::make_unique<LinkBridge>(
        io_, link_config.bridge, [this, &l](std::span<const std::uint8_t> bytes) { write_to_link(l, bytes); });
  }
  if (link_config.feedback.enabled) l.feedback.emplace(link_config.format, link_config.feedback);
  links_.push_back(std::move(link));
}

void Daemon::add_sinks() {
  sinks_.push_back(std::make_unique<RecordingSink>(*this));
  std::vector<LiveLink> live;
  for (auto& link : links_) {
    live.push_back({.name = link->config.name,
                    .format = link->config.format,
                    .feedback = link->feedback ? &*link->feedback : nullptr,
                    .bridge = link->bridge.get(),
                    .write = [this, &l = *link](std::span<const std::uint8_t> bytes) { write_to_link(l, bytes); }});
  }
  const LiveContext context{.io = io_,
                            .outputs = *outputs_,
                            .config = config_.outputs,
                            .record_event = [this](std::optional<std::size_t> link, std::string kind,
                                                   std::string detail, std::int64_t count) {
                              record([&](Recording& r) {
                                r.store.append_event(
                                    r.session, {.link_id = link ? std::optional(r.store_links.at(*link)) : std::nullopt,
                                                .mono_ns = mono_now_ns(),
                                                .wall_ns = wall_now_ns(),
                                                .kind = std::move(kind),
                                                .count = count,
                                                .detail = std::move(detail)});
                              });
                            }};
  for (auto& sink : make_live_sinks(context, live)) sinks_.push_back(std::move(sink));
  for (auto& sink : sinks_) engine_->add_sink(*sink);
}

Daemon::~Daemon() = default;

int Daemon::run() {
  for (auto& link : links_) link->port->start();
  wait_for_signal();
  every(commit_timer_, config_.store.commit_interval, &Daemon::commit_tick);
  every(stats_timer_, config_.stats_interval, &Daemon::stats_tick);
  every(resume_timer_, kStorageRetryInterval, &Daemon::resume_tick);
  // From the event loop, so a loop stuck for WatchdogSec is what systemd restarts.
  if (auto period = systemd_.watchdog_period()) every(watchdog_timer_, *period, &Daemon::watchdog_tick);
  systemd_.ready(status_line());
  spdlog::info("running: {}", status_line());
  // Its own thread and store connection: recording never waits for the archive. Stopped when the loop ends.
  std::optional<ArchiveSyncThread> archive_sync;
  if (config_.sync) archive_sync.emplace(*config_.sync, config_.store.path);
  io_.run();
  return 0;
}

void Daemon::stop() {
  boost::asio::post(io_, [this] { shutdown(); });
}

// --- Links -------------------------------------------------------------------------------------------------------

void Daemon::on_open(Link& link, const std::string& path, bool reopened) {
  const std::int64_t mono = mono_now_ns();
  std::string detail = path;
  if (reopened && link.lost_at_ns) detail += fmt::format(" after {:.1f} s", (mono - *link.lost_at_ns) * 1e-9);
  record([&](Recording& r) {
    r.store.append_event(r.session, {.link_id = r.store_links[link.index],
                                     .mono_ns = mono,
                                     .wall_ns = wall_now_ns(),
                                     .kind = reopened ? "reconnect" : "connected",
                                     .detail = detail});
  });
  systemd_.status(status_line());
  request_streams(link);
}

// The configured stream rates, asked again at every (re)open: a vehicle that rebooted forgot them.
void Daemon::request_streams(Link& link) {
  const LinkConfig& c = link.config;
  if (c.format != protocol::WireFormat::mavlink || c.request_rates.empty()) return;
  const auto [system, component] = link.vehicle.value_or(std::pair<std::uint8_t, std::uint8_t>{0, 0});
  std::string asked;
  for (const auto& [name, hz] : c.request_rates) {
    const auto msgid = mavlink_message_id(name);  // checked when the config was read
    if (!msgid) continue;
    write_to_link(link, set_message_interval(*msgid, hz, system, component,
                                             {.seq = link.gcs_seq++, .sysid = c.gcs_sysid, .compid = c.gcs_compid}));
    asked += fmt::format("{}{} at {} Hz", asked.empty() ? "" : ", ", name, hz);
  }
  spdlog::info("link '{}': asked {} for {} (MAV_CMD_SET_MESSAGE_INTERVAL)", c.name,
               link.vehicle ? fmt::format("system {}, component {}", system, component)
                            : std::string("every system (not heard yet)"),
               asked);
}

void Daemon::on_lost(Link& link, const std::string& reason) {
  link.lost_at_ns = mono_now_ns();
  record([&](Recording& r) {
    r.store.append_event(r.session, {.link_id = r.store_links[link.index],
                                     .mono_ns = *link.lost_at_ns,
                                     .wall_ns = wall_now_ns(),
                                     .kind = "link_lost",
                                     .detail = reason});
  });
  systemd_.status(status_line());
}

void Daemon::on_data(Link& link, std::span<const std::uint8_t> bytes) {
  engine_->on_chunk(link.index, bytes, mono_now_ns(), wall_now_ns());
  if (link.config.format == protocol::WireFormat::mavlink) {
    const pipeline::LinkDecoder& decoder = engine_->decoder(link.index);
    const auto imu = decoder.mavlink_imu();
    if (imu) {
      link.vehicle.emplace(imu->sysid, imu->compid);
    } else if (!link.vehicle) {
      for (const auto& m : decoder.mavlink_messages()) {
        if (m.sysid == link.config.gcs_sysid) continue;  // a ground station's own frames, echoed or bridged
        link.vehicle.emplace(m.sysid, m.compid);
        break;
      }
    }
    if (imu && imu != link.logged_imu) {
      link.logged_imu = imu;
      spdlog::info("link '{}': samples from {} only: the first IMU heard{}", link.config.name,
                   protocol::mavlink::describe(*imu), link.config.imu ? " of those 'imu' names" : "");
    }
    for (const auto& change : link.land_detector.after(decoder)) {
      spdlog::info(
          "link '{}': the autopilot (system {}) says {}", link.config.name, change.system,
          change.landed ? "landed: the velocity is held at rest" : "no longer landed: the velocity is the drag's");
    }
  }
  record([&](Recording& r) { commits_ += r.store.commit_if_due(Clock::now()); });
}

// Bytes for the vehicle (velocity feedback, a ground-control station's commands) are recorded as tx chunks.
void Daemon::write_to_link(Link& link, std::span<const std::uint8_t> bytes) {
  if (!link.port->write(bytes)) return;
  ++link.tx_chunks;
  record([&](Recording& r) {
    r.store.append_chunk(r.session, r.store_links[link.index], store::Direction::tx, mono_now_ns(), wall_now_ns(),
                         bytes);
  });
}

// --- Operations --------------------------------------------------------------------------------------------------

void Daemon::wait_for_signal() {
  signals_.async_wait([this](const boost::system::error_code& ec, int signal) {
    if (ec) return;
    if (signal == SIGHUP) {
      reload();
    } else if (signal == SIGUSR1) {
      log_stats();
    } else {
      spdlog::info("{}: stopping", signal == SIGINT ? "SIGINT" : "SIGTERM");
      return shutdown();
    }
    wait_for_signal();
  });
}

// SIGHUP: the outputs, logging and free-space settings of the configuration file take effect, and the log file is
// reopened (after logrotate moved it). Links and the rest of the store keep running as they are: changing them needs
// a restart.
void Daemon::reload() {
  if (config_file_) {
    try {
      const Config fresh = load_config(*config_file_);
      outputs_->reconfigure(fresh.outputs);
      config_.outputs = fresh.outputs;
      config_.log_level = fresh.log_level;
      config_.log_file = fresh.log_file;
      config_.store.min_free_bytes = fresh.store.min_free_bytes;  // the next check of free space applies it
    } catch (const std::exception& e) {
      spdlog::error("SIGHUP: {}; keeping the running configuration", e.what());
    }
  }
  try {
    configure_logging(config_);
  } catch (const spdlog::spdlog_ex& e) {
    spdlog::error("SIGHUP: cannot reopen the log: {}", e.what());
  }
  spdlog::info("SIGHUP: reloaded {}", config_file_ ? config_file_->string() : "the log (no configuration file)");
}

void Daemon::every(boost::asio::steady_timer& timer, std::chrono::nanoseconds period, void (Daemon::*tick)()) {
  timer.expires_after(period);
  timer.async_wait([this, &timer, period, tick](const boost::system::error_code& ec) {
    if (ec) return;  // cancelled: stopping
    (this->*tick)();
    every(timer, period, tick);
  });
}

void Daemon::commit_tick() {
  record([&](Recording& r) {
    if (r.store.pending_rows() > 0) {
      r.store.commit();
      ++commits_;
    }
  });
  check_storage();
}

void Daemon::stats_tick() {
  log_stats();
  systemd_.status(status_line());
}

void Daemon::log_stats() const { spdlog::info("stats {}", counters().dump()); }

void Daemon::watchdog_tick() { systemd_.watchdog(); }

void Daemon::shutdown() {
  if (stopping_) return;
  stopping_ = true;
  systemd_.stopping();
  for (auto& link : links_) link->port->stop();
  boost::system::error_code ignored;
  signals_.cancel(ignored);
  commit_timer_.cancel();
  stats_timer_.cancel();
  watchdog_timer_.cancel();
  resume_timer_.cancel();
  finish_links();
  close_recording();
  log_stats();
  io_.stop();
}

// The end of every link's stream: what the decoders still hold is decoded, estimated and recorded, and sources still
// deciding their IMU axes release their estimates. Only the recording hears it: it comes too late for the outputs.
void Daemon::finish_links() {
  for (std::size_t i = 1; i < sinks_.size(); ++i) engine_->remove_sink(*sinks_[i]);  // sinks_[0]: RecordingSink
  const std::int64_t mono = mono_now_ns(), wall = wall_now_ns();
  for (std::size_t i = 0; i < links_.size(); ++i) engine_->finish_link(i, mono, wall);
  engine_->finish();
}

std::string Daemon::status_line() const {
  std::string status =
      recording_ ? fmt::format("recording session {} into {}", recording_->session, recording_->path.string())
      : not_recording_
          ? fmt::format(
                "not recording: {}; links and outputs go on{}", not_recording_->reason,
                not_recording_->resumes
                    ? fmt::format(" (resumes once {} is free)",
                                  mib(config_.store.min_free_bytes + resume_margin(config_.store.min_free_bytes)))
                    : "")
          : std::string("not recording");
  for (const auto& link : links_) {
    status += fmt::format("; {} {} ({} samples)", link->config.name,
                          link->port->is_open() ? link->port->path() : "waiting for " + describe(link->config.device),
                          link->samples);
  }
  return status;
}

nlohmann::json Daemon::counters() const {
  nlohmann::json links = nlohmann::json::object();
  for (const auto& link : links_) {
    const SerialLink::Counters& port = link->port->counters();
    nlohmann::json decoders = nlohmann::json::object();
    for (const auto& [layer, counters] : engine_->decoder(link->index).counters()) decoders[layer] = counters;
    nlohmann::json j{{"device", link->port->is_open() ? nlohmann::json(link->port->path()) : nlohmann::json()},
                     {"bytes_read", port.bytes_read},
                     {"reads", port.reads},
                     {"decoders", decoders},
                     {"samples", link->samples},
                     {"estimates", link->estimates},
                     {"opens", port.opens},
                     {"losses", port.losses},
                     {"failed_opens", port.failed_opens},
                     {"tx",
                      {{"chunks", link->tx_chunks},
                       {"bytes_written", port.bytes_written},
                       {"bytes_dropped", port.bytes_dropped_tx},
                       {"queue_bytes", port.tx_queue_bytes}}}};
    if (link->bridge) j["bridge"] = link->bridge->counters();
    if (link->feedback) j["feedback"] = link->feedback->counters();
    links[link->config.name] = std::move(j);
  }
  nlohmann::json store{{"recording", recording_ != nullptr}, {"commits", commits_}, {"rotations", rotations_}};
  if (recording_) {
    store["path"] = recording_->path.string();
    store["session"] = recording_->session;
    store["pending_rows"] = recording_->store.pending_rows();
    store["size_bytes"] = database_size(recording_->path);
  }
  return {{"links", links}, {"store", store}, {"outputs", outputs_->counters()}};
}

}  // namespace imubridge::daemon
