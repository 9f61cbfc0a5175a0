#pragma once
// The model a diagnosis ends with, as the live estimator runs it: a fitted diagnose::Model (base plus effects) turned
// into PARAMS.json's estimator::ModelParams, so `run`, `replay` and `evaluate` estimate with exactly what the loop
// found (docs/effects.md, "Live"). The base's parameters are mapped here; each effect maps its own
// (Effect::live_path, Effect::to_live).
#include <span>
#include <string>
#include <vector>

#include "diagnose/model.hpp"
#include "estimator/params.hpp"

namespace imubridge::diagnose {

// The PARAMS.json path of each of the model's parameters ("full.lever_arm.0", "paper.x.mu", "full.drag_linear.1",
// "effects.vibration.f"), under which live_params records its standard error; empty for the one PARAMS.json keeps
// otherwise (the filter's process noise, fitted as its log10: identification.process_noise).
std::vector<std::string> parameter_paths(const Model& model);

// The parameters of `model` at `values`; standard errors, when given, go into identification.std_errors under the
// same path as the value they belong to.
estimator::ModelParams live_params(const Model& model, std::span<const double> values,
                                   std::span<const double> std_errors = {});

// The identification block of a fit: method, windows, and per diagnosed axis the residual RMS over the whole band
// (the filter's measurement noise follows it: estimator::config_for), keyed "<full|paper>.<axis>.<fit|validation>".
void record_fit(estimator::ModelParams& params, const Model& model, std::span<const double> values, Range train,
                Range validation);

}  // namespace imubridge::diagnose
