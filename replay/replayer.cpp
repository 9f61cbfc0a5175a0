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
#include "replay/session_lookup.hpp"

namespace imubridge::replay {
namespace {

constexpr std::uint32_t kNoLink = 0;  // SQLite never gives a row the id 0

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
      return radio == ids->end() ? kNoLink : static_cast<std::uint32_t>(radio->second);
    };
    decoders.emplace(
        port->second,
        ReplayedLink{recorded.name, pipeline::LinkDecoder(recorded.format, static_cast<std::uint32_t>(port->second),
                                                          recorded.calibration, std::move(resolve))});
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
        axes.links[static_cast<std::uint32_t>(link.id)] = estimator::parse_imu_axes(r.imu_axes);
        break;
      }
    }
  }
  return axes;
}

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
  // The links' axes as recorded, so a replay rotates (and, for auto links, decides) exactly as the live run did.
  pipeline::EstimationStage stage(params, recorded_axes(store, session));
  std::vector<store::Estimate> estimates;

  ReplayResult result;
  std::vector<protocol::Sample> samples;
  const auto estimate = [&] {
    for (const auto& sample : samples) {
      if (sample.link_id == kNoLink) {
        ++result.samples_without_link;
        continue;
      }
      ++result.samples;
      stage.update(sample, estimates);
    }
    samples.clear();
    for (const store::Estimate& e : estimates) store.append_estimate(result.run, e);
    result.estimates += estimates.size();
    estimates.clear();
  };
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
    link.decoder.feed(chunk.bytes, chunk.recv_mono_ns, samples);
    link.last_mono_ns = chunk.recv_mono_ns;
    link.fed = true;
    estimate();
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
    link.decoder.finish(link.last_mono_ns, samples);  // as the recorder does at the end of its stream
    estimate();
    for (const auto& [layer, counters] : link.decoder.counters()) result.counters[link.name] += counters;
  }
  stage.finish(estimates);  // links still deciding their axes release their samples, as a live run's close does
  for (const store::Estimate& e : estimates) store.append_estimate(result.run, e);
  result.estimates += estimates.size();
  store.commit();
  return result;
}

}  // namespace imubridge::replay
