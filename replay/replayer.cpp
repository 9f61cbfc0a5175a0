#include "replay/replayer.hpp"

#include <chrono>
#include <memory>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <vector>

#include "pipeline/estimation_stage.hpp"
#include "pipeline/link_decoder.hpp"
#include "pipeline/radio_link.hpp"
#include "pipeline/session_config.hpp"
#include "pipeline/session_engine.hpp"
#include "replay/session_lookup.hpp"

namespace imubridge::replay {
namespace {

constexpr protocol::LinkId kNoLink = 0;  // SQLite never gives a row the id 0

std::int64_t wall_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

struct ReplayedLink {
  std::string name;
  pipeline::LinkDecoder decoder;
  std::int64_t last_mono_ns = 0;
  bool fed = false;
};

// A decoder per recorded link, keyed by the port link's store id. XBee radios resolve to the links the recorder made
// for them (pipeline/radio_link.hpp), so replayed samples carry the recorded link ids.
std::map<std::int64_t, ReplayedLink> make_decoders(const store::Store& store, const store::Session& session) {
  auto ids = std::make_shared<std::map<std::string, std::int64_t>>();  // shared with the decoders' radio resolvers
  for (const auto& link : store.links(session.id)) ids->try_emplace(link.name, link.id);
  std::map<std::int64_t, ReplayedLink> decoders;
  for (const auto& recorded : pipeline::recorded_links(session.info.config)) {
    const auto port = ids->find(recorded.name);
    if (port == ids->end()) {
      throw std::invalid_argument("session " + std::to_string(session.id) + " records link \"" + recorded.name +
                                  "\" in its config but has no such link");
    }
    auto resolve = [ids, link = recorded.name](std::uint64_t source64) {
      const auto radio = ids->find(pipeline::radio_link_name(link, source64));
      return radio == ids->end() ? kNoLink : radio->second;
    };
    auto& replayed =
        decoders
            .emplace(port->second, ReplayedLink{recorded.name, pipeline::LinkDecoder(
                                                                   recorded.format, port->second, recorded.calibration,
                                                                   std::move(resolve), recorded.mavlink_imu)})
            .first->second;
    if (recorded.mavlink_imu_lock) replayed.decoder.lock_mavlink_imu(*recorded.mavlink_imu_lock);
  }
  return decoders;
}

// Each store link's IMU axes as the session recorded them: a radio's link has the axes of the link it was heard
// through.
pipeline::StageAxes recorded_axes(const store::Store& store, const store::Session& session) {
  pipeline::StageAxes axes;
  const auto recorded = pipeline::recorded_links(session.info.config);
  for (const auto& link : store.links(session.id)) {
    const auto radio = pipeline::parse_radio_link_name(link.name);
    for (const auto& r : recorded) {
      if (link.name == r.name || (radio && radio->link == r.name)) {
        axes.links[link.id] = estimator::parse_imu_axes(r.imu_axes);
        break;
      }
    }
  }
  return axes;
}

// Replay's decoding: the recorded link's decoder, without the samples of radios the session never recorded (they
// have no store link to be estimated under); those are counted.
class RecordedLinksOnly final : public pipeline::ChunkDecoding {
 public:
  RecordedLinksOnly(pipeline::LinkDecoder& decoder, ReplayResult& result) : decoder_(decoder), result_(result) {}
  void decode(std::span<const std::uint8_t> bytes, std::int64_t recv_mono_ns, std::int64_t,
              std::vector<protocol::Sample>& out) override {
    decoder_.feed(bytes, recv_mono_ns, out);
    drop_unrecorded(out);
  }
  void finish(std::int64_t mono_ns, std::int64_t, std::vector<protocol::Sample>& out) override {
    decoder_.finish(mono_ns, out);
    drop_unrecorded(out);
  }

 private:
  void drop_unrecorded(std::vector<protocol::Sample>& samples) {
    result_.samples_without_link +=
        std::erase_if(samples, [](const protocol::Sample& s) { return s.link_id == kNoLink; });
  }
  pipeline::LinkDecoder& decoder_;
  ReplayResult& result_;
};

// Replay's one sink: the estimates, into the new run.
class RunSink final : public pipeline::SessionSink {
 public:
  RunSink(store::Store& store, ReplayResult& result) : store_(store), result_(result) {}
  void on_sample(std::size_t, const protocol::Sample&, std::span<const store::Estimate> estimates,
                 std::int64_t) override {
    ++result_.samples;
    append(estimates);
  }
  void on_final_estimates(std::span<const store::Estimate> estimates) override { append(estimates); }

 private:
  void append(std::span<const store::Estimate> estimates) {
    for (const store::Estimate& e : estimates) store_.append_estimate(result_.run, e);
    result_.estimates += estimates.size();
  }
  store::Store& store_;
  ReplayResult& result_;
};

}  // namespace

estimator::ModelParams replay_params(const store::Store& store, std::int64_t session) {
  for (const auto& run : store.runs(session)) {
    if (run.info.kind == "live") return estimator::parse_params(run.info.params_json, "run " + std::to_string(run.id));
  }
  return {};
}

ReplayResult replay_session(store::Store& store, std::int64_t session_id, const ReplayOptions& options) {
  const store::Session session = find_session(store, session_id);
  const estimator::ModelParams params = options.params ? *options.params : replay_params(store, session_id);
  auto decoders = make_decoders(store, session);
  ReplayResult result;
  RunSink run(store, result);
  // The links' axes as recorded, so a replay rotates (and, for auto links, decides) exactly as the live run did.
  pipeline::SessionEngine engine(std::make_unique<pipeline::EstimationStage>(params, recorded_axes(store, session)));
  engine.add_sink(run);
  play_chunks(store, session, options.play, [&](const store::Chunk& chunk, double t_s) {
    const auto it = decoders.find(chunk.link_id);
    if (it == decoders.end()) {
      ++result.chunks_without_link;
      return;
    }
    if (result.run == 0) {  // created with the first chunk: a window without any leaves no empty run behind
      result.run = store.begin_run(
          session_id,
          {.kind = "replay", .params_json = nlohmann::json(params).dump(), .created_wall_ns = wall_now_ns()});
      result.first_s = t_s;
    }
    ReplayedLink& link = it->second;
    RecordedLinksOnly decoding(link.decoder, result);
    engine.on_chunk(static_cast<std::size_t>(it->first), decoding, chunk.bytes, chunk.recv_mono_ns, chunk.recv_wall_ns);
    link.last_mono_ns = chunk.recv_mono_ns;
    link.fed = true;
    ++result.chunks;
    result.bytes += chunk.bytes.size();
    result.last_s = t_s;
    store.commit_if_due(std::chrono::steady_clock::now());
    if (options.progress) options.progress(t_s);
  });
  if (result.run == 0) {
    throw std::invalid_argument("session " + std::to_string(session_id) + " has no recorded bytes" +
                                (options.play.from_s || options.play.to_s ? " in that time window" : ""));
  }
  for (auto& [id, link] : decoders) {
    if (!link.fed) continue;
    RecordedLinksOnly decoding(link.decoder, result);
    engine.finish_link(static_cast<std::size_t>(id), decoding, link.last_mono_ns, link.last_mono_ns);
    for (const auto& [layer, counters] : link.decoder.counters()) result.counters[link.name] += counters;
  }
  engine.finish();  // links still deciding their axes release their samples, as a live run's close does
  store.commit();
  return result;
}

}  // namespace imubridge::replay
