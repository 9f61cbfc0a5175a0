#include "identification/identify_choices.hpp"

#include <array>
#include <stdexcept>
#include <string>
#include <utility>

namespace imubridge::estimator {
namespace {

template <typename Enum, std::size_t N>
Enum parse(std::string_view text, const std::array<std::pair<std::string_view, Enum>, N>& names, const char* what) {
  std::string valid;
  for (const auto& [spelling, value] : names) {
    if (text == spelling) return value;
    valid += (valid.empty() ? "" : ", ") + std::string(spelling);
  }
  throw std::invalid_argument("unknown " + std::string(what) + " \"" + std::string(text) + "\" (valid: " + valid + ")");
}

template <typename Enum, std::size_t N>
std::string_view spelling(Enum value, const std::array<std::pair<std::string_view, Enum>, N>& names) {
  for (const auto& [text, v] : names) {
    if (v == value) return text;
  }
  return "?";
}

constexpr std::array<std::pair<std::string_view, ModelKind>, 2> kModels{
    {{"paper", ModelKind::paper}, {"full", ModelKind::full}}};
constexpr std::array<std::pair<std::string_view, Method>, 3> kMethods{
    {{"ga", Method::ga}, {"lm", Method::lm}, {"ga+lm", Method::ga_lm}}};
constexpr std::array<std::pair<std::string_view, VelocitySource>, 3> kVelocities{
    {{"eq12", VelocitySource::eq12}, {"reference", VelocitySource::reference}, {"filter", VelocitySource::filter}}};

}  // namespace

std::string_view name(ModelKind model) { return spelling(model, kModels); }
std::string_view name(Method method) { return spelling(method, kMethods); }
std::string_view name(VelocitySource velocity) { return spelling(velocity, kVelocities); }
ModelKind parse_model(std::string_view text) { return parse(text, kModels, "model"); }
Method parse_method(std::string_view text) { return parse(text, kMethods, "method"); }
VelocitySource parse_velocity(std::string_view text) { return parse(text, kVelocities, "velocity source"); }

}  // namespace imubridge::estimator
