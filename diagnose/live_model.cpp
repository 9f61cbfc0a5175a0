#include "diagnose/live_model.hpp"

#include <cmath>

#include "identification/identify.hpp"

namespace imubridge::diagnose {

std::vector<std::string> parameter_paths(const Model& model) {
  const ModelSetup& setup = model.setup();
  const std::vector<Parameter>& parameters = model.parameters();
  std::vector<std::string> paths(parameters.size());
  if (setup.base == ModelKind::full) {
    for (int i = 0; i < 3; ++i) {
      paths[i] = "full.lever_arm." + std::to_string(i);
      paths[3 + i] = "full.mounting." + std::to_string(i);
    }
  } else {
    for (std::size_t i = 0; i < setup.axes.size(); ++i) {
      const std::string prefix = setup.axes[i] == 0 ? "paper.x." : "paper.y.";
      paths[4 * i] = prefix + "r", paths[4 * i + 1] = prefix + "beta", paths[4 * i + 2] = prefix + "alpha";
      paths[4 * i + 3] = prefix + "mu";
    }
  }
  for (std::size_t e = 0; e < model.effects().size(); ++e) {
    for (std::size_t i = model.effect_offset(e); i < model.effect_offset(e) + model.effect_size(e); ++i)
      paths[i] = model.effects()[e]->live_path(parameters[i]);
  }
  return paths;
}

estimator::ModelParams live_params(const Model& model, std::span<const double> p, std::span<const double> std_errors) {
  const ModelSetup& setup = model.setup();
  const std::vector<Parameter>& parameters = model.parameters();
  estimator::ModelParams out;
  estimator::FullModelParams& full = out.full;

  if (setup.base == ModelKind::full) {
    for (int i = 0; i < 3; ++i) {
      full.lever_arm[i] = p[i];
      full.mounting[i] = p[3 + i];
    }
  } else {
    for (std::size_t i = 0; i < setup.axes.size(); ++i) {
      const estimator::PaperAxisParams axis{p[4 * i], p[4 * i + 1], p[4 * i + 2], p[4 * i + 3]};
      (setup.axes[i] == 0 ? out.paper_x : out.paper_y) = axis;
    }
    full = estimator::full_from_paper(out.paper_x, out.paper_y);
  }
  if (setup.velocity == VelocitySource::filter) out.identification.process_noise = model.process_noise(p);
  const LiveContext context{
      .setup = setup,
      .imu_to_body = setup.base == ModelKind::full ? rotation_matrix(full.mounting) : Eigen::Matrix3d::Identity(),
      .first_attitude = [&]() -> std::optional<Eigen::Quaterniond> {
        const ModelInputs inputs = model.inputs(p);
        if (inputs.attitude.empty()) return std::nullopt;
        return inputs.attitude.front();
      }};
  const std::span<const Parameter> all(parameters);
  for (std::size_t e = 0; e < model.effects().size(); ++e) {
    const Effect& effect = *model.effects()[e];
    out.effects.emplace_back(effect.name());
    if (const auto why = effect.live_refusal()) out.not_live[std::string(effect.name())] = *why;
    const std::size_t first = model.effect_offset(e), size = model.effect_size(e);
    effect.to_live(p.subspan(first, size), all.subspan(first, size), context, full);
  }

  if (!std_errors.empty()) {
    const std::vector<std::string> paths = parameter_paths(model);
    for (std::size_t i = 0; i < paths.size() && i < std_errors.size(); ++i) {
      if (!paths[i].empty() && std::isfinite(std_errors[i])) out.identification.std_errors[paths[i]] = std_errors[i];
    }
  }
  return out;
}

void record_fit(estimator::ModelParams& params, const Model& model, std::span<const double> p, Range train,
                Range validation) {
  const ModelSetup& setup = model.setup();
  const Signals& signals = model.signals();
  estimator::Identification& id = params.identification;
  id.method = "diagnose";
  const auto window = [&](Range r) {
    const double end =
        r.first + r.count < signals.size() ? signals.t[r.first + r.count] : signals.t.back() + 1.0 / signals.rate_hz;
    return estimator::TimeWindow{signals.t[r.first], end};
  };
  id.fit_windows = {window(train)};
  id.validation_windows = {window(validation)};
  // The live filter sees the whole band, so its noise comes from the residual without the band limit.
  ModelSetup whole_band = setup;
  whole_band.lowpass_hz = 0.0;
  const Model unfiltered(signals, whole_band, model.effects());
  const std::string model_name = setup.base == ModelKind::full ? "full." : "paper.";
  for (const auto& [set, range] : {std::pair{"fit", train}, std::pair{"validation", validation}}) {
    const AxisValues residual = unfiltered.evaluate(p, range).residual();
    for (std::size_t i = 0; i < residual.size(); ++i) {
      double sum = 0.0;
      for (double r : residual[i]) sum += r * r;
      id.rmse[model_name + axis_name(setup.axes[i]) + "." + set] =
          std::sqrt(sum / static_cast<double>(std::max<std::size_t>(residual[i].size(), 1)));
    }
  }
}

}  // namespace imubridge::diagnose
