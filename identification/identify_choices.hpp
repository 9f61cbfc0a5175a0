#pragma once
// The choices an identification (identification/identify.hpp) and a diagnosis (diagnose/) are made with, and their
// command-line spellings: which model, which solver, which velocity the drag term sees.
#include <string_view>

namespace imubridge::estimator {

enum class ModelKind { paper, full };  // "paper": eq. (14) per axis; "full": the 3-D rigid body and mounting
enum class Method { ga, lm, ga_lm };   // "ga", "lm", "ga+lm"
// "eq12": eq. (12), integrated from the gyro (3-D: dead_reckon); "reference": the session's reference trajectory;
// "filter": the drag-velocity filter running the model being fitted, by the filter error method
// (diagnose/filter_identification.hpp: it needs diagnose's model, so identify() refuses it).
enum class VelocitySource { eq12, reference, filter };

std::string_view name(ModelKind model);
std::string_view name(Method method);
std::string_view name(VelocitySource velocity);
// Throw std::invalid_argument naming the valid spellings.
ModelKind parse_model(std::string_view text);
Method parse_method(std::string_view text);
VelocitySource parse_velocity(std::string_view text);

}  // namespace imubridge::estimator
