#include "replay/chunk_player.hpp"

#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>
#include <thread>

namespace imubridge::replay {
namespace {

void validate(const PlayOptions& o) {
  const auto finite_at_least = [](std::optional<double> v, double low) {
    return !v || (std::isfinite(*v) && *v >= low);
  };
  if (!finite_at_least(o.from_s, 0) || !finite_at_least(o.to_s, 0)) {
    throw std::invalid_argument("--from and --to are seconds from the session's start: finite, not negative");
  }
  if (o.to_s && *o.to_s <= o.from_s.value_or(0)) throw std::invalid_argument("--to must come after --from");
  if (o.speed && !(std::isfinite(*o.speed) && *o.speed > 0)) {
    throw std::invalid_argument("the speed must be a positive multiple of real time, or max");
  }
}

}  // namespace

std::uint64_t play_chunks(const store::Store& store, const store::Session& session, const PlayOptions& options,
                          const ChunkVisitor& visit) {
  validate(options);
  using Clock = std::chrono::steady_clock;
  std::optional<std::int64_t> start_mono;  // the session's start on the chunks' monotonic clock
  std::optional<std::pair<std::int64_t, Clock::time_point>> pace_origin;  // first visited chunk: recorded, now
  std::uint64_t visited = 0;
  store.for_each_chunk(session.id, options.link, [&](const store::Chunk& chunk) {
    if (!start_mono) start_mono = chunk.recv_mono_ns - (chunk.recv_wall_ns - session.info.started_wall_ns);
    if (chunk.direction != store::Direction::rx) return;  // what we sent the vehicle is not part of its stream
    const double t_s = static_cast<double>(chunk.recv_mono_ns - *start_mono) * 1e-9;
    if ((options.from_s && t_s < *options.from_s) || (options.to_s && t_s >= *options.to_s)) return;
    if (options.speed) {
      if (!pace_origin) pace_origin.emplace(chunk.recv_mono_ns, Clock::now());
      const auto recorded = std::chrono::nanoseconds(chunk.recv_mono_ns - pace_origin->first);
      std::this_thread::sleep_until(pace_origin->second +
                                    std::chrono::duration_cast<Clock::duration>(recorded / *options.speed));
    }
    ++visited;
    visit(chunk, t_s);
  });
  return visited;
}

}  // namespace imubridge::replay
