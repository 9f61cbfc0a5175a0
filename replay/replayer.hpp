#pragma once
// Replay: a recorded session's bytes through the very stages that recorded and estimated it live, a LinkDecoder per
// recorded link (format and calibration from the session's config snapshot) and the EstimationStage, into a new run
// of kind "replay". The same chunks and parameters give the live run's estimates bit for bit. docs/replay.md.
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <string_view>

#include "estimator/params.hpp"
#include "protocol/decoder_counters.hpp"
#include "replay/chunk_player.hpp"
#include "store/store.hpp"

namespace imubridge::replay {

struct ReplayOptions {
  std::optional<estimator::ModelParams> params{};  // nullopt: replay_params()
  PlayOptions play{};
  std::function<void(double t_s)> progress{};  // after each chunk, with its receive time from the session's start
};

struct ReplayResult {
  std::int64_t run = 0;
  std::uint64_t chunks = 0, bytes = 0, samples = 0, estimates = 0;
  // Not replayed, because the session has no store link for them (a chunk of a link its config does not record, a
  // sample of an XBee radio it never recorded). A faithful session has none.
  std::uint64_t chunks_without_link = 0, samples_without_link = 0;
  double first_s = 0, last_s = 0;  // receive times of the first and last replayed chunks, from the session's start
  std::map<std::string, protocol::DecoderCounters> counters;  // by link name, summed over its framing layers
};

// What a replay uses unless told otherwise: the parameters of the session's live run, the defaults if it has none.
estimator::ModelParams replay_params(const store::Store& store, std::int64_t session);

// Throws std::invalid_argument when the session is unknown, records no usable links, or has no chunk to replay.
ReplayResult replay_session(store::Store& store, std::int64_t session, const ReplayOptions& options = {});

}  // namespace imubridge::replay
