#pragma once
// A session's received bytes as they arrived: the rx chunks of one link or of all, in recorded order, within a time
// window and, if asked, at their recorded pace. Replay feeds them to the decoders; `replay --to-pty` writes them to a
// pseudo-terminal. Both see the same chunks by the same rule.
#include <cstdint>
#include <functional>
#include <optional>

#include "store/store.hpp"

namespace imubridge::replay {

struct PlayOptions {
  // The window [from_s, to_s), in seconds from the session's start, compared with each chunk's receive time.
  std::optional<double> from_s{}, to_s{};
  // Pace as a multiple of real time; nullopt plays as fast as possible.
  std::optional<double> speed{};
  // A port link's store id; nullopt plays every link.
  std::optional<std::int64_t> link{};
};

// t_s: the chunk's receive time in seconds from the session's start.
using ChunkVisitor = std::function<void(const store::Chunk& chunk, double t_s)>;

// Visits the chunks and returns how many it visited. The session's start is its started_wall_ns, put on the
// monotonic clock the chunks are stamped with by the first chunk's (recv_wall_ns, recv_mono_ns) pair. With a speed,
// each chunk is visited once its receive time, counted from the first visited chunk's and divided by the speed, has
// passed. Throws std::invalid_argument for a window or speed that is not a positive, finite, ordered pair or value.
std::uint64_t play_chunks(const store::Store& store, const store::Session& session, const PlayOptions& options,
                          const ChunkVisitor& visit);

}  // namespace imubridge::replay
