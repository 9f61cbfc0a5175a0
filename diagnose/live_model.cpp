#include "diagnose/live_model.hpp"

#include <cmath>
#include <stdexcept>

#include "estimator/identify.hpp"

namespace imubridge::diagnose {
namespace {

using Eigen::Vector3d;

// "k.x" -> 0, "bias.z" -> 2: the axis letter a per-axis parameter's name ends with.
int axis_of(const std::string& name) {
  const char last = name.empty() ? '?' : name.back();
  if (last < 'x' || last > 'z') throw std::logic_error("diagnose: parameter " + name + " names no axis");
  return last - 'x';
}

// The yaw (rad) of a body -> NED attitude.
double yaw_of(const Eigen::Quaterniond& q) {
  const Eigen::Matrix3d r = q.toRotationMatrix();
  return std::atan2(r(1, 0), r(0, 0));
}

}  // namespace

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
    const std::string name(model.effects()[e]->name());
    for (std::size_t i = model.effect_offset(e); i < model.effect_offset(e) + model.effect_size(e); ++i) {
      const std::string& pname = parameters[i].name;
      const auto per_axis = [&](const char* block) {
        return "full." + std::string(block) + "." + std::to_string(axis_of(pname));
      };
      if (name == "linear_drag") {
        paths[i] = per_axis("drag_linear");
      } else if (name == "quadratic_drag") {
        paths[i] = per_axis("drag_quadratic");
      } else if (name == "wind") {
        paths[i] = std::string("full.wind.") + (pname == "north" ? "0" : "1");
      } else if (name == "accel_bias") {
        paths[i] = per_axis("accel_bias");
      } else if (name == "accel_scale") {
        paths[i] = per_axis("accel_scale");
      } else if (name == "accel_cross") {  // "cross.xy": axis x reads a fraction of axis y
        paths[i] =
            "full.accel_cross." + std::to_string(pname[pname.size() - 2] - 'x') + std::to_string(pname.back() - 'x');
      } else if (name == "gyro_bias") {
        paths[i] = per_axis("gyro_bias");
      } else if (name == "time_offset") {
        paths[i] = "full.time_offset";
      } else {
        // lever_arm_z (the 3-D lever arm has its z), vibration (refused live, with its reason, when PARAMS.json is
        // read): kept under the effect's own name.
        paths[i] = "effects." + name + "." + pname;
      }
    }
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
  // The full model's residual frame is the body's: a bias found there is R_bs^T b in IMU axes.
  const Eigen::Matrix3d imu_to_body =
      setup.base == ModelKind::full ? rotation_matrix(full.mounting) : Eigen::Matrix3d::Identity();

  for (std::size_t e = 0; e < model.effects().size(); ++e) {
    const std::string name(model.effects()[e]->name());
    out.effects.push_back(name);
    Vector3d body_bias = Vector3d::Zero();
    for (std::size_t i = model.effect_offset(e); i < model.effect_offset(e) + model.effect_size(e); ++i) {
      const std::string& pname = parameters[i].name;
      const double v = p[i];
      if (name == "linear_drag") {
        full.drag_linear[axis_of(pname)] += v;
      } else if (name == "quadratic_drag") {
        full.drag_quadratic[axis_of(pname)] += v;
      } else if (name == "wind") {
        full.wind[pname == "north" ? 0 : 1] = v;
      } else if (name == "accel_bias") {
        body_bias[axis_of(pname)] = v;
      } else if (name == "accel_scale") {
        full.accel_scale[axis_of(pname)] = v;
      } else if (name == "accel_cross") {  // "cross.xy": axis x reads a fraction of axis y
        full.accel_cross(pname[pname.size() - 2] - 'x', pname.back() - 'x') = v;
      } else if (name == "gyro_bias") {
        full.gyro_bias[axis_of(pname)] = v;
      } else if (name == "time_offset") {
        full.time_offset = v;
      }
      // lever_arm_z and vibration have no place in the estimator's parameters (parameter_paths says where they go).
    }
    if (name == "accel_bias") full.accel_bias += imu_to_body.transpose() * body_bias;
    // The world the wind was fitted in: the model's attitude at the first sample. The filter's heading starts at 0
    // there, which is the default.
    if (name == "wind" && setup.velocity != VelocitySource::filter) {
      const ModelInputs inputs = model.inputs(p);
      if (!inputs.attitude.empty()) full.wind_heading = yaw_of(inputs.attitude.front());
    }
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
