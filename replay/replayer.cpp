#include "replay/replayer.hpp"

#include <chrono>
#include <memory>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <vector>

#include "pipeline/estimation_stage.hpp"
#include "pipeline/land_detector.hpp"
#include "pipeline/link_decoder.hpp"
#include "pipeline/radio_link.hpp"
#include "pipeline/session_config.hpp"
#include "pipeline/session_engine.hpp"
#include "replay/session_lookup.hpp"

namespace imubridge::replay {
namespace {

std::int64_t wall_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

struct ReplayedLink {
  std::size_t index;  // in the engine: the link's place among the session's recorded links, as it was live
  std::string name;
  std::int64_t last_mono_ns = 0;
  bool fed = false;
};

// The session's recorded links as the engine's, in their recorded order (the order the live run numbered them), by
// the port's store link; their store links, and those the recording made for XBee radios, by source.
struct ReplayedLinks {
  std::map<std::int64_t, ReplayedLink> by_row;
  std::map<protocol::SourceKey, std::int64_t> rows;
};

ReplayedLinks add_links(pipeline::SessionEngine& engine, const store::Store& store, const store::Session& session) {
  std::map<std::string, std::int64_t> ids;
  for (const auto& link : store.links(session.id)) ids.try_emplace(link.name, link.id);
  ReplayedLinks links;
  for (const auto& recorded : pipeline::recorded_links(session.info.config)) {
    const auto port = ids.find(recorded.name);
    if (port == ids.end()) {
      throw std::invalid_argument("session " + std::to_string(session.id) + " records link \"" + recorded.name +
                                  "\" in its config but has no such link");
    }
    const std::size_t index = engine.add_link(pipeline::make_decoder(recorded));
    links.by_row.emplace(port->second, ReplayedLink{index, recorded.name});
    links.rows[{.link = static_cast<std::uint32_t>(index)}] = port->second;
    for (const auto& [name, id] : ids) {
      const auto radio = pipeline::parse_radio_link_name(name);
      if (radio && radio->link == recorded.name) {
        links.rows[{.link = static_cast<std::uint32_t>(index), .radio = radio->source64}] = id;
      }
    }
  }
  return links;
}

// Each recorded link's IMU axes as the session recorded them (a radio's are those of the link it is heard through).
pipeline::StageAxes recorded_axes(const store::Session& session) {
  pipeline::StageAxes axes;
  const auto recorded = pipeline::recorded_links(session.info.config);
  for (std::size_t i = 0; i < recorded.size(); ++i) {
    axes.links[static_cast<std::uint32_t>(i)] = estimator::parse_imu_axes(recorded[i].imu_axes);
  }
  return axes;
}

// Replay's one sink: the estimates, into the new run, under the store links the session recorded. Samples of radios
// the session never recorded have no store link to be estimated under; those are counted.
class RunSink final : public pipeline::SessionSink {
 public:
  RunSink(store::Store& store, const std::map<protocol::SourceKey, std::int64_t>& rows, ReplayResult& result)
      : store_(store), rows_(rows), result_(result) {}
  void on_sample(std::size_t, const protocol::Sample& sample, std::span<const store::Estimate> estimates,
                 std::int64_t) override {
    if (!rows_.contains(sample.source)) {
      ++result_.samples_without_link;
      return;
    }
    ++result_.samples;
    append(sample.source, estimates);
  }
  void on_final_estimates(const protocol::SourceKey& source, std::span<const store::Estimate> estimates) override {
    if (rows_.contains(source)) append(source, estimates);
  }

 private:
  void append(const protocol::SourceKey& source, std::span<const store::Estimate> estimates) {
    for (store::Estimate e : estimates) {
      e.link_id = rows_.at(source);
      store_.append_estimate(result_.run, e);
    }
    result_.estimates += estimates.size();
  }
  store::Store& store_;
  const std::map<protocol::SourceKey, std::int64_t>& rows_;
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
  // The links' axes as recorded, so a replay rotates (and, for auto links, decides) exactly as the live run did.
  pipeline::SessionEngine engine(std::make_unique<pipeline::EstimationStage>(params, recorded_axes(session)));
  ReplayedLinks links = add_links(engine, store, session);
  ReplayResult result;
  RunSink run(store, links.rows, result);
  engine.add_sink(run);
  // An imported log's land detector, stored as takeoff and landing events, at its time on the chunks' clock. A
  // MAVLink link's own (EXTENDED_SYS_STATE) comes with its bytes, which the engine reads as the live run did: stored
  // events never override it.
  pipeline::StoredLandDetector land_detector(store.events(session_id));
  const auto set_landed = [&](const std::optional<std::int64_t>& link_id, bool landed) {
    for (const auto& [row, link] : links.by_row) {
      if ((!link_id || *link_id == row) && engine.decoder(link.index).format() != protocol::WireFormat::mavlink) {
        engine.stage()->set_landed(static_cast<std::uint32_t>(link.index), landed);
      }
    }
  };
  if (land_detector.landed_at_start()) set_landed(std::nullopt, true);
  play_chunks(store, session, options.play, [&](const store::Chunk& chunk, double t_s) {
    const auto it = links.by_row.find(chunk.link_id);
    if (it == links.by_row.end()) {
      ++result.chunks_without_link;
      return;
    }
    for (const auto& change : land_detector.until(chunk.recv_mono_ns)) set_landed(change.link_id, change.landed);
    if (result.run == 0) {  // created with the first chunk: a window without any leaves no empty run behind
      result.run = store.begin_run(
          session_id,
          {.kind = "replay", .params_json = nlohmann::json(params).dump(), .created_wall_ns = wall_now_ns()});
      result.first_s = t_s;
    }
    ReplayedLink& link = it->second;
    engine.on_chunk(link.index, chunk.bytes, chunk.recv_mono_ns, chunk.recv_wall_ns);
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
  for (auto& [row, link] : links.by_row) {
    if (!link.fed) continue;
    engine.finish_link(link.index, link.last_mono_ns, link.last_mono_ns);
    for (const auto& [layer, counters] : engine.decoder(link.index).counters()) result.counters[link.name] += counters;
  }
  engine.finish();  // links still deciding their axes release their samples, as a live run's close does
  store.commit();
  return result;
}

}  // namespace imubridge::replay
