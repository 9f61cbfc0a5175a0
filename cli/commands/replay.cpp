// `imubridge replay`: a recorded session through the live pipeline again, into a new run beside the live one, or
// its recorded bytes re-emitted on a pseudo-terminal at their recorded pace. docs/replay.md.

#include <CLI/CLI.hpp>
#include <algorithm>
#include <charconv>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>

#include "cli/command.hpp"
#include "cli/pty.hpp"
#include "estimator/params.hpp"
#include "pipeline/session_config.hpp"
#include "replay/session_series.hpp"
#include "replay/replayer.hpp"
#include "replay/session_lookup.hpp"

namespace imubridge::cli {
namespace {

using Clock = std::chrono::steady_clock;

struct ReplayCommandOptions {
  std::string db;
  std::int64_t session = 0;
  std::string params, speed, to_pty, link;
  std::optional<double> from_s, to_s;
};

volatile std::sig_atomic_t g_stop = 0;
extern "C" void on_replay_stop_signal(int) { g_stop = 1; }
struct Stopped {};  // thrown out of the chunk loop once a signal asked us to stop

// "max" (nothing: no pacing) or a positive multiple of real time (checked by play_chunks).
std::optional<double> parse_speed(const std::string& text) {
  if (text == "max") return std::nullopt;
  double speed = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), speed);
  if (error != std::errc() || end != text.data() + text.size()) {
    throw std::invalid_argument("--speed: expected a multiple of real time or max, not \"" + text + "\"");
  }
  return speed;
}

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::invalid_argument(path + ": cannot be read");
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// The store link a --link name means; without one, the session's only recorded link (a pty carries one stream).
std::int64_t link_id(const store::Store& store, const store::Session& session, std::string name) {
  if (name.empty()) {
    const auto recorded = pipeline::recorded_links(session.info.config);
    std::string names;
    for (const auto& link : recorded) names += (names.empty() ? "" : ", ") + link.name;
    if (recorded.size() != 1) {
      throw std::invalid_argument("session " + std::to_string(session.id) + " has " + std::to_string(recorded.size()) +
                                  " links (" + names + "): choose one with --link");
    }
    name = recorded.front().name;
  }
  for (const auto& link : store.links(session.id)) {
    if (link.name == name) return link.id;
  }
  throw std::invalid_argument("session " + std::to_string(session.id) + " has no link \"" + name + "\"");
}

// A progress line on stderr, redrawn at most ten times a second, only for a person watching a terminal.
class Progress {
 public:
  Progress(double from_s, std::optional<double> to_s) : from_s_(from_s), to_s_(to_s), shown_(isatty(STDERR_FILENO)) {}
  ~Progress() { clear(); }

  void clear() {  // before anything else is printed
    if (drawn_) std::fputs("\r\033[K", stderr);
    drawn_ = false;
  }

  void update(double t_s) {
    if (!shown_ || Clock::now() < next_) return;
    next_ = Clock::now() + std::chrono::milliseconds(100);
    drawn_ = true;
    if (!to_s_) {
      std::fprintf(stderr, "\r%.1f s", t_s);
      return;
    }
    const double done = std::clamp((t_s - from_s_) / (*to_s_ - from_s_), 0.0, 1.0);
    const int width = 40, filled = static_cast<int>(done * width);
    std::fprintf(stderr, "\r[%s%s] %5.1f / %.1f s", std::string(filled, '#').c_str(),
                 std::string(width - filled, '.').c_str(), t_s, *to_s_);
  }

 private:
  double from_s_;
  std::optional<double> to_s_;
  bool shown_, drawn_ = false;
  Clock::time_point next_{};
};

// Where the progress bar ends: --to, or the last moment the session records, its end or its last event (a simulated
// or imported session ends faster than it lasts, but the recorder's final "counters" event is stamped in its time).
std::optional<double> progress_end(const store::Store& store, const store::Session& session,
                                   std::optional<double> to_s) {
  if (to_s) return to_s;
  std::optional<std::int64_t> last_wall_ns = session.ended_wall_ns;
  for (const auto& e : store.events(session.id)) last_wall_ns = std::max(last_wall_ns.value_or(e.wall_ns), e.wall_ns);
  if (!last_wall_ns || *last_wall_ns <= session.info.started_wall_ns) return std::nullopt;
  return static_cast<double>(*last_wall_ns - session.info.started_wall_ns) * 1e-9;
}

void print_losses(const replay::ReplayResult& r) {
  for (const auto& [link, c] : r.counters) {
    if (c.crc_failures + c.bytes_discarded + c.frames_lost + c.duplicates == 0) continue;
    std::fprintf(stderr, "  %s: %llu frames lost, %llu CRC failures, %llu bytes discarded, %llu duplicates\n",
                 link.c_str(), static_cast<unsigned long long>(c.frames_lost),
                 static_cast<unsigned long long>(c.crc_failures), static_cast<unsigned long long>(c.bytes_discarded),
                 static_cast<unsigned long long>(c.duplicates));
  }
  if (r.chunks_without_link + r.samples_without_link > 0) {
    std::fprintf(stderr, "  not replayed, for want of a link in the session: %llu chunks, %llu samples\n",
                 static_cast<unsigned long long>(r.chunks_without_link),
                 static_cast<unsigned long long>(r.samples_without_link));
  }
}

int replay_into_run(const ReplayCommandOptions& o) {
  store::Store store(o.db);
  const store::Session session = replay::find_session(store, o.session);
  replay::ReplayOptions options;
  if (!o.params.empty()) {
    // The session's own flight keeps the conditions fitted on it; another flies the vehicle's calibration alone.
    const replay::SessionSeries flight = replay::read_session_series(
        store, o.session, {.link = o.link.empty() ? std::nullopt : std::optional(link_id(store, session, o.link))});
    std::string left;
    options.params =
        estimator::for_flight(estimator::parse_params(read_file(o.params), o.params), flight.flight, &left);
    if (!left.empty()) std::fprintf(stderr, "%s\n", left.c_str());
  }
  options.play = {.from_s = o.from_s, .to_s = o.to_s, .speed = parse_speed(o.speed.empty() ? "max" : o.speed)};
  if (!o.link.empty()) options.play.link = link_id(store, session, o.link);
  Progress progress(o.from_s.value_or(0), progress_end(store, session, o.to_s));
  options.progress = [&progress](double t_s) { progress.update(t_s); };
  const auto start = Clock::now();
  const replay::ReplayResult r = replay::replay_session(store, o.session, options);
  const double wall_s = std::chrono::duration<double>(Clock::now() - start).count();
  const double recorded_s = r.last_s - r.first_s;
  progress.clear();
  std::fprintf(stderr, "%s\n", replay::describe_state(session).c_str());  // once it worked: a mistake is one line
  std::fprintf(stderr,
               "replayed session %lld into run %lld: %llu samples, %llu estimates from %llu chunks; %.1f s recorded "
               "in %.2f s (%.0fx real time)\n",
               static_cast<long long>(o.session), static_cast<long long>(r.run),
               static_cast<unsigned long long>(r.samples), static_cast<unsigned long long>(r.estimates),
               static_cast<unsigned long long>(r.chunks), recorded_s, wall_s, recorded_s / wall_s);
  print_losses(r);
  std::printf("%lld\n", static_cast<long long>(r.run));
  return 0;
}

int replay_to_pty(const ReplayCommandOptions& o) {
  const store::Store store(o.db, {.read_only = true});
  const store::Session session = replay::find_session(store, o.session);
  const replay::PlayOptions play{.from_s = o.from_s,
                                 .to_s = o.to_s,
                                 .speed = parse_speed(o.speed.empty() ? "1" : o.speed),
                                 .link = link_id(store, session, o.link)};
  PtyPair pty(o.to_pty);
  std::fprintf(stderr, "%s\n", replay::describe_state(session).c_str());
  std::fprintf(stderr, "replaying session %lld's bytes on %s (%s); Ctrl-C stops\n", static_cast<long long>(o.session),
               o.to_pty.c_str(), pty.slave_name().c_str());
  std::signal(SIGINT, on_replay_stop_signal);
  std::signal(SIGTERM, on_replay_stop_signal);
  Progress progress(o.from_s.value_or(0), progress_end(store, session, o.to_s));
  std::uint64_t bytes = 0;
  double first_s = 0, last_s = 0;
  try {
    replay::play_chunks(store, session, play, [&](const store::Chunk& chunk, double t_s) {
      if (g_stop) throw Stopped{};
      if (bytes == 0) first_s = t_s;
      pty.write(chunk.bytes);
      bytes += chunk.bytes.size();
      last_s = t_s;
      progress.update(t_s);
    });
  } catch (const Stopped&) {
  }
  progress.clear();
  const auto unread = static_cast<unsigned long long>(pty.drain());  // closing discards what is unread
  std::fprintf(stderr, "sent %llu bytes (%.1f s of the recording)", static_cast<unsigned long long>(bytes),
               last_s - first_s);
  if (pty.dropped_bytes() + unread > 0) {
    std::fprintf(stderr, "; nobody was reading: %llu bytes dropped, at least %llu left unread",
                 static_cast<unsigned long long>(pty.dropped_bytes()), unread);
  }
  std::fprintf(stderr, "\n");
  return 0;
}

const RegisterCommand kReplay([](CLI::App& app) -> CommandRunner {
  auto o = std::make_shared<ReplayCommandOptions>();
  auto* cmd = app.add_subcommand("replay", "Run a recorded session through the pipeline again, into a new run");
  cmd->add_option("--db", o->db, "The session store")->required();
  cmd->add_option("--session", o->session, "The session to replay")->required();
  auto* params =
      cmd->add_option("--params", o->params, "PARAMS.json to estimate with (default: the live run's, else defaults)");
  cmd->add_option("--speed", o->speed, "Pace: a multiple of real time, or max (default: max; 1 with --to-pty)");
  cmd->add_option("--from", o->from_s, "Start this many seconds after the session's start (decoders start fresh)");
  cmd->add_option("--to", o->to_s, "Stop this many seconds after the session's start");
  cmd->add_option("--link", o->link, "Replay this link only (needed with --to-pty when a session has several)");
  auto* pty = cmd->add_option("--to-pty", o->to_pty,
                              "Re-emit the recorded bytes on a pseudo-terminal linked at this path, instead of a run");
  params->excludes(pty);
  cmd->footer("Prints the new run's id alone on the last line of stdout; a summary goes to stderr.");
  return [o] {
    replay::require_existing_store(o->db);
    return o->to_pty.empty() ? replay_into_run(*o) : replay_to_pty(*o);
  };
});

}  // namespace
}  // namespace imubridge::cli
