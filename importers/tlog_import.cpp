#include "importers/tlog_import.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <span>
#include <stdexcept>
#include <utility>
#include <variant>
#include <vector>

#include "importers/euroc_import.hpp"
#include "importers/import_session.hpp"
#include "importers/tlog.hpp"
#include "pipeline/mavlink_reference.hpp"
#include "protocol/mavlink.hpp"

namespace imubridge::importers {
namespace {

namespace mavlink = protocol::mavlink;

constexpr std::uint32_t kStatusTextId = 253;  // STATUSTEXT: severity, then char[50] text
constexpr double kMicroteslaPerMilligauss = 0.1;

std::int64_t ns(std::uint64_t us) { return static_cast<std::int64_t>(us) * 1000; }

using Component = std::pair<std::uint8_t, std::uint8_t>;  // system id, component id

// IMU messages in order of preference between IMUs that send equally many: float fields and µs times first.
int preference(std::uint32_t msgid) {
  switch (msgid) {
    case mavlink::HighresImu::kId:
      return 0;
    case mavlink::ScaledImu::kId:
      return 1;
    case mavlink::RawImu::kId:
      return 2;
    case mavlink::ScaledImu2::kId:
      return 3;
    default:
      return 4;
  }
}

constexpr std::array<std::string_view, 5> kImuMessages{"HIGHRES_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3",
                                                       "RAW_IMU"};

// An int16 accelerometer or gyro field at the end of its range: the sender could not say more.
template <typename M>
bool at_range_end(const M& m) {
  if constexpr (std::is_same_v<decltype(m.xacc), std::int16_t>) {
    for (const std::int16_t v : {m.xacc, m.yacc, m.zacc, m.xgyro, m.ygyro, m.zgyro}) {
      if (v == std::numeric_limits<std::int16_t>::max() || v == std::numeric_limits<std::int16_t>::min()) return true;
    }
  }
  return false;
}

bool clipped(const mavlink::Decoded& decoded) {
  return std::visit(
      []<typename M>(const M& m) {
        if constexpr (requires { m.xacc; }) {
          return at_range_end(m);
        } else {
          return false;
        }
      },
      decoded);
}

struct StatusText {
  std::size_t record = 0;
  std::uint8_t severity = 0;
  std::string text;
};

// What the first pass over the log finds: every IMU and its messages, the reference's messages, the strings.
struct Survey {
  std::map<mavlink::ImuSource, std::uint64_t> imus, clipped;
  std::map<std::string, std::uint64_t> messages;  // by name
  // The reference's candidates (pipeline::MavlinkReference builds it): LOCAL_POSITION_NED by sender, and the
  // senders of a usable (unit) ATTITUDE_QUATERNION.
  std::map<Component, std::uint64_t> positions;
  std::set<Component> quaternions;
  std::vector<StatusText> strings;
};

std::string message_name(std::uint32_t msgid) {
  const mavlink::MessageSpec* spec = mavlink::message_spec(msgid);
  return spec ? std::string(spec->name) : "id " + std::to_string(msgid);
}

// Firmware text for JSON and the store: printable ASCII, up to the first NUL.
std::string clean_text(std::span<const std::uint8_t> bytes) {
  std::string out;
  for (const std::uint8_t c : bytes) {
    if (c == 0) break;
    out += c >= 0x20 && c < 0x7f ? static_cast<char>(c) : '?';
  }
  return out;
}

std::string severity_name(std::uint8_t severity) {
  static const char* const kNames[] = {"emergency", "alert", "critical", "error", "warning", "notice", "info", "debug"};
  return severity < 8 ? kNames[severity] : "severity " + std::to_string(severity);
}

Survey survey(const tlog::Log& log) {
  Survey s;
  mavlink::Decoder decoder;  // as the recorder's will: retransmissions dropped, restarts counted
  std::vector<mavlink::Message> out;
  for (std::size_t i = 0; i < log.records.size(); ++i) {
    out.clear();
    decoder.feed(log.frame(log.records[i]), out);
    for (const mavlink::Message& m : out) {
      ++s.messages[message_name(m.msgid)];
      const Component from{m.sysid, m.compid};
      if (m.msgid == kStatusTextId && m.len > 0) {
        s.strings.push_back({i, m.payload[0], clean_text(std::span(m.payload).subspan(1, 50))});
      }
      const std::optional<mavlink::Decoded> decoded = mavlink::decode(m);
      if (!decoded) continue;
      if (const auto imu = mavlink::imu_source(m)) {
        ++s.imus[*imu];
        if (clipped(*decoded)) ++s.clipped[*imu];
      } else if (std::holds_alternative<mavlink::LocalPositionNed>(*decoded)) {
        ++s.positions[from];
      } else if (const auto* aq = std::get_if<mavlink::AttitudeQuaternion>(&*decoded)) {
        const Eigen::Quaterniond q(aq->q1, aq->q2, aq->q3, aq->q4);
        if (std::abs(q.norm() - 1) <= 1e-2) s.quaternions.insert(from);  // as MavlinkReference accepts one
      }
    }
  }
  return s;
}

// The IMU to import: of the candidates, the one with the most messages (the highest rate over the log), then by
// preference(), then by sender and id.
std::optional<mavlink::ImuSource> choose_imu(const Survey& s, const TlogImportOptions& options, bool raw_calibrated) {
  std::optional<mavlink::ImuSource> best;
  std::uint64_t best_count = 0;
  for (const auto& [source, count] : s.imus) {
    if (source.msgid == mavlink::RawImu::kId && !raw_calibrated) continue;
    if (options.imu_message && message_name(source.msgid) != *options.imu_message) continue;
    if (!best || count > best_count || (count == best_count && preference(source.msgid) < preference(best->msgid))) {
      best = source;
      best_count = count;
    }
  }
  return best;
}

std::string imu_list(const Survey& s) {
  std::string text;
  for (const auto& [source, count] : s.imus) {
    text += (text.empty() ? "" : "; ") + mavlink::describe(source) + ": " + std::to_string(count);
  }
  return text;
}

// The reference's sender and attitude message, as pipeline::MavlinkReference is to take them: the IMU's sender when
// it sends positions, else the sender of the most; ATTITUDE_QUATERNION when that sender sent any usable, else
// ATTITUDE. Nothing when no sender sends positions.
std::optional<pipeline::MavlinkReference::Choice> reference_choice(const Survey& s, Component imu_sender) {
  if (s.positions.empty()) return std::nullopt;
  Component from = s.positions.begin()->first;
  for (const auto& [c, n] : s.positions) {
    if (n > s.positions.at(from)) from = c;
  }
  if (s.positions.contains(imu_sender)) from = imu_sender;
  return pipeline::MavlinkReference::Choice{.sender = from, .quaternions = s.quaternions.contains(from)};
}

// The samples the engine decodes: counted, and kept for the holes and the check of the declared IMU axes against
// gravity.
class SamplesSink final : public pipeline::SessionSink {
 public:
  explicit SamplesSink(std::int64_t t0_ns) : t0_ns_(t0_ns) {}
  void on_sample(std::size_t, const protocol::Sample& s, std::span<const store::Estimate>, std::int64_t) override {
    samples.add(static_cast<double>(s.recv_mono_ns - t0_ns_) * 1e-9, s.recv_mono_ns, s.accel, s.gyro);
  }
  ImportedSamples samples;

 private:
  std::int64_t t0_ns_;
};

nlohmann::json source_json(const mavlink::ImuSource& s) {
  return {{"description", mavlink::describe(s)},
          {"message", message_name(s.msgid)},
          {"msgid", s.msgid},
          {"sysid", s.sysid},
          {"compid", s.compid},
          {"id", s.id}};
}

nlohmann::json by_id(const std::map<std::uint32_t, std::uint64_t>& counts) {
  nlohmann::json j = nlohmann::json::object();
  for (const auto& [id, n] : counts) j[std::to_string(id)] = n;
  return j;
}

nlohmann::json metadata(const tlog::Log& log, const Survey& s, const TlogImportOptions& options,
                        const mavlink::ImuSource& imu, const std::string& reference) {
  nlohmann::json imus = nlohmann::json::array();
  for (const auto& [source, count] : s.imus) {
    nlohmann::json j = source_json(source);
    j["messages"] = count;
    imus.push_back(j);
  }
  nlohmann::json damage = nlohmann::json::array();
  for (const tlog::Damage& d : log.damage) {
    damage.push_back({{"offset", d.offset}, {"bytes", d.bytes}, {"after_records", d.record}, {"what", d.what}});
  }
  return {{"import",
           {{"format", "tlog"},
            {"file", options.file.string()},
            {"imu_source", source_json(imu)},
            {"imus", imus},
            {"reference", reference},
            {"accel_lsb", options.accel_lsb ? nlohmann::json(*options.accel_lsb) : nlohmann::json(nullptr)},
            {"gyro_lsb", options.gyro_lsb ? nlohmann::json(*options.gyro_lsb) : nlohmann::json(nullptr)},
            {"records", log.records.size()},
            {"first_us", log.records.front().time_us},
            {"last_us", log.records.back().time_us},
            {"messages", s.messages},
            {"unverified", log.unverified},
            {"unknown_ids", by_id(log.unknown_ids)},
            {"other_layout_ids", by_id(log.other_layout_ids)},
            {"damage", damage}}}};
}

// The options checked before anything is read; the calibration RAW_IMU's counts are decoded with (the other IMU
// messages carry SI-scaled values and need none).
protocol::Calibration checked_calibration(const TlogImportOptions& options) {
  if (options.accel_lsb.has_value() != options.gyro_lsb.has_value()) {
    throw std::invalid_argument("RAW_IMU needs both resolutions: --accel-lsb and --gyro-lsb");
  }
  check_gap_threshold(options.gap_threshold_s);
  protocol::Calibration calibration;
  if (options.accel_lsb) {
    calibration = import_calibration(*options.accel_lsb, *options.gyro_lsb);
    calibration.mag.scale.fill(kMicroteslaPerMilligauss);
    if (!calibration.valid() || !(*options.accel_lsb > 0) || !(*options.gyro_lsb > 0)) {
      throw std::invalid_argument("the accelerometer and gyro resolutions must be positive and finite");
    }
  }
  if (options.imu_message && std::ranges::find(kImuMessages, *options.imu_message) == kImuMessages.end()) {
    throw std::invalid_argument("--imu-message " + *options.imu_message +
                                ": not an IMU message (HIGHRES_IMU, SCALED_IMU, SCALED_IMU2, SCALED_IMU3, RAW_IMU)");
  }
  return calibration;
}

// The session's clock is the log's, held still while the log's time goes back (a ground station's clock set back),
// so chunks, samples, reference and events keep one increasing time line; the wall clock is the log's as written.
std::vector<std::int64_t> session_clock(const tlog::Log& log) {
  std::vector<std::int64_t> mono_ns(log.records.size());
  for (std::size_t i = 0; i < log.records.size(); ++i) {
    mono_ns[i] = i == 0 ? ns(log.records[i].time_us) : std::max(mono_ns[i - 1], ns(log.records[i].time_us));
  }
  return mono_ns;
}

// Why no IMU can be imported, for the error.
std::string no_imu_message(const std::string& file, const tlog::Log& log, const Survey& s,
                           const TlogImportOptions& options, bool raw_calibrated) {
  std::string why;
  if (s.imus.empty()) {
    why = "no IMU messages (HIGHRES_IMU, SCALED_IMU, SCALED_IMU2, SCALED_IMU3 or RAW_IMU) in its " +
          std::to_string(log.records.size()) + " records";
  } else if (options.imu_message) {
    why =
        "no " + *options.imu_message + " messages" +
        (raw_calibrated || *options.imu_message != "RAW_IMU" ? ""
                                                             : " that can be used without --accel-lsb and --gyro-lsb") +
        " (its IMUs: " + imu_list(s) + ")";
  } else {
    why =
        "its only IMU messages are RAW_IMU, which carry counts: give their resolution with --accel-lsb and "
        "--gyro-lsb (ArduPilot sends mG and mrad/s: 0.00980665 and 0.001)";
  }
  return file + ": " + why + (log.damage.empty() ? "" : "; the file is damaged: " + *log.damage_summary());
}

// Messages of the IMUs not imported (by IMU and why), and of the one imported those with a value at its field's end.
struct ImuProblems {
  std::map<std::string, std::uint64_t> skipped;
  std::uint64_t clipped = 0;
};

// Every IMU's messages into the result; those of the IMUs not imported, and the imported one's clipped values.
ImuProblems count_imus(const Survey& s, const mavlink::ImuSource& imu, bool raw_calibrated, TlogImportResult& result) {
  ImuProblems problems;
  result.imu_source = mavlink::describe(imu);
  for (const auto& [source, count] : s.imus) {
    result.imu_messages[mavlink::describe(source)] = count;
    if (source == imu) continue;
    const bool raw_without = source.msgid == mavlink::RawImu::kId && !raw_calibrated;
    problems.skipped[mavlink::describe(source) + (raw_without ? ": RAW_IMU counts without --accel-lsb and --gyro-lsb"
                                                              : ": not the IMU imported")] += count;
  }
  if (const auto c = s.clipped.find(imu); c != s.clipped.end()) problems.clipped = c->second;
  return problems;
}

void describe_log(const tlog::Log& log, TlogImportResult& result) {
  result.records = log.records.size();
  result.unverified = log.unverified;
  result.unverified_summary = log.unverified_summary();
  result.first_us = log.records.front().time_us;
  result.last_us = log.records.back().time_us;
}

// Every frame fed to the session, the link finished at the last record; the reference's rows counted as its
// recorder built them.
ImportedSamples record_frames(ImportSession& session, const tlog::Log& log, const std::vector<std::int64_t>& mono_ns,
                              const TlogImportOptions& options, TlogImportResult& result) {
  SamplesSink sink(mono_ns.front());
  session.add_sink(sink);
  const auto progress = [&](std::uint64_t bytes_read) {
    options.progress({.bytes_read = bytes_read, .bytes_total = log.bytes.size(), .samples = sink.samples.t.size()});
  };
  for (std::size_t i = 0; i < log.records.size(); ++i) {
    session.feed(log.frame(log.records[i]), mono_ns[i], ns(log.records[i].time_us));
    if (options.progress && (i + 1) % kImportProgressEvery == 0) {
      progress(log.records[i].offset + tlog::kTimeSize + log.records[i].size);
    }
  }
  if (options.progress) progress(log.bytes.size());
  session.finish_link(mono_ns.back(), ns(log.records.back().time_us));
  result.samples = sink.samples.t.size();
  if (const pipeline::MavlinkReference* built = session.recorder().mavlink_reference()) {
    result.reference_rows = built->rows();
  }
  if (result.reference_rows == 0) result.reference_source.clear();
  return std::move(sink.samples);
}

// Events at a record's time: the session's clock and the log's wall clock there.
struct RecordTimes {
  const tlog::Log& log;
  const std::vector<std::int64_t>& mono_ns;

  EventAt operator()(std::optional<std::int64_t> on, std::size_t record) const {
    return {.link = on, .mono_ns = mono_ns[record], .wall_ns = ns(log.records[record].time_us)};
  }
};

// The firmware's texts, then the log's own holes and its clock going back.
void record_log_events(ImportSession& session, const RecordTimes& at, const Survey& s, TlogImportResult& result) {
  for (const StatusText& t : s.strings) {
    session.log_event(at(std::nullopt, t.record), "log", severity_name(t.severity) + ": " + t.text);
    ++result.log_events;
  }
  const tlog::Log& log = at.log;
  for (std::size_t i = 1; i < log.records.size(); ++i) {
    const std::uint64_t before = log.records[i - 1].time_us, now = log.records[i].time_us;
    if (now > before + kTlogGapUs) {
      const double gap = static_cast<double>(now - before) * 1e-6;
      char text[96];
      std::snprintf(text, sizeof text, "no record in the log for %.1f s", gap);
      session.log_event(at(session.link(), i - 1), "log_gap", text);
      ++result.log_gaps;
      result.log_gap_s += gap;
    } else if (now < before) {
      char text[160];
      std::snprintf(text, sizeof text,
                    "the log's time went back %.3f s (its clock set back?); the session's clock waits for it",
                    static_cast<double>(before - now) * 1e-6);
      session.log_event(at(session.link(), i), "log_time_back", text);
      ++result.time_back;
    }
  }
}

// Each damaged stretch where it lies: the records around it are imported.
void report_damage(ImportSession& session, const RecordTimes& at, const std::string& file) {
  for (const tlog::Damage& d : at.log.damage) {
    const std::string where =
        "at byte " + std::to_string(d.offset) +
        (d.record == 0 ? ", before the first record" : ", after record " + std::to_string(d.record));
    session.report({.kind = ProblemKind::damaged,
                    .count = d.bytes,
                    .what = "bytes of " + file,
                    .why = d.what + "; the records around them are imported",
                    .where = where},
                   at(std::nullopt, d.record == 0 ? 0 : d.record - 1),
                   file + ": " + std::to_string(d.bytes) + " bytes at byte " + std::to_string(d.offset) +
                       " are no record (" + d.what + "); the records around them are imported");
  }
}

// What the import left out or found clipped, at the last record; each damaged stretch where it lies.
void report_problems(ImportSession& session, const RecordTimes& at, const std::string& file, const ImuProblems& imu) {
  const EventAt on_link = at(session.link(), at.log.records.size() - 1);
  const EventAt on_session = at(std::nullopt, at.log.records.size() - 1);
  for (const auto& [reason, count] : imu.skipped) {
    session.report({.kind = ProblemKind::skipped, .count = count, .what = "IMU messages", .why = reason}, on_link,
                   file + ": " + std::to_string(count) + " IMU messages: " + reason);
  }
  if (const pipeline::MavlinkReference* built = session.recorder().mavlink_reference()) {
    for (const auto& [reason, count] : built->skipped()) {
      session.report({.kind = ProblemKind::skipped, .count = count, .what = "reference rows", .why = reason},
                     on_session, file + ": " + std::to_string(count) + " reference rows: " + reason);
    }
  }
  if (imu.clipped > 0) {
    const std::string why = "a value at the end of its field's range (clipped by the sender?)";
    session.report({.kind = ProblemKind::clipped, .count = imu.clipped, .what = "samples", .why = why}, on_link,
                   file + ": " + std::to_string(imu.clipped) + " samples with " + why);
  }
  report_damage(session, at, file);
}

// The session's start: its source, the metadata, the link of the log's frames with the IMU and the reference chosen.
pipeline::SessionStart session_start(const tlog::Log& log, const Survey& s, const TlogImportOptions& options,
                                     const mavlink::ImuSource& imu, const TlogImportResult& result) {
  return {.kind = "import",
          .source = "MAVLink telemetry log " + options.file.string(),
          .config = metadata(log, s, options, imu, result.reference_source),
          .started_wall_ns = ns(result.first_us)};
}

}  // namespace

TlogImportResult import_tlog(store::Store& store, const TlogImportOptions& options) {
  const estimator::ImuAxes declared_axes = estimator::parse_imu_axes(options.imu_axes);
  const protocol::Calibration calibration = checked_calibration(options);
  const bool raw_calibrated = options.accel_lsb.has_value();
  const tlog::Log log = tlog::read_file(options.file);
  const std::string file = options.file.string();

  TlogImportResult result;
  const std::vector<std::int64_t> mono_ns = session_clock(log);
  const Survey s = survey(log);
  const std::optional<mavlink::ImuSource> imu = choose_imu(s, options, raw_calibrated);
  if (!imu) throw std::invalid_argument(no_imu_message(file, log, s, options, raw_calibrated));
  const ImuProblems imu_problems = count_imus(s, *imu, raw_calibrated, result);
  // The reference rows are built as the frames are recorded, by the recorder (as on a live link).
  std::optional<pipeline::MavlinkReference::Choice> reference;
  if (options.reference) reference = reference_choice(s, Component{imu->sysid, imu->compid});
  if (reference) result.reference_source = pipeline::MavlinkReference(*reference).source();
  describe_log(log, result);

  ImportSession session(store, session_start(log, s, options, *imu, result),
                        {.recorded = {"telemetry", protocol::WireFormat::mavlink, calibration, options.imu_axes, *imu},
                         .device = "MAVLink telemetry log " + file + ", samples from " + result.imu_source,
                         .mavlink_reference = reference},
                        options.on_problem);
  result.session = session.id();
  const ImportedSamples samples = record_frames(session, log, mono_ns, options, result);

  const RecordTimes at{.log = log, .mono_ns = mono_ns};
  record_log_events(session, at, s, result);
  report_problems(session, at, file, imu_problems);
  ImportChecks checks = session.end(samples, options.gap_threshold_s, mono_ns.front(), declared_axes,
                                    at(session.link(), log.records.size() - 1),
                                    std::max(ns(log.records.back().time_us), ns(result.first_us)));
  result.gaps = std::move(checks.gaps);
  result.axes = std::move(checks.axes);
  return result;
}

}  // namespace imubridge::importers
