#include "diagnose/report_parts.hpp"

#include <cmath>
#include <stdexcept>

#include "fileio/whole_file.hpp"

namespace imubridge::diagnose::report_parts {

using nlohmann::json;

json number(double value) { return std::isfinite(value) ? json(value) : json(nullptr); }

std::string axis_name(const Diagnosis& d, std::size_t index) {
  return index < d.axes.size() ? d.axes[index] : std::to_string(index);
}

const ResidualAnalysis* analysis_for(const Diagnosis& d, const std::vector<ResidualAnalysis>& residuals,
                                     const std::string& axis) {
  for (std::size_t i = 0; i < residuals.size() && i < d.axes.size(); ++i) {
    if (d.axes[i] == axis) return &residuals[i];
  }
  return nullptr;
}

std::string join(const std::vector<std::string>& items, std::string_view separator) {
  std::string out;
  for (const auto& item : items) out += (out.empty() ? "" : std::string(separator)) + item;
  return out;
}

void write_text(const std::filesystem::path& file, const std::string& text) {
  fileio::write_whole_file(file, text);
}

}  // namespace imubridge::diagnose::report_parts
