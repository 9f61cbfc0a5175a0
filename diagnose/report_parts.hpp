#pragma once
// What report.json, the plots and report.html share (diagnose/report.hpp is the public face): internal to
// diagnose/report_*.cpp.
#include <cstddef>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "diagnose/diagnosis.hpp"
#include "diagnose/gnuplot.hpp"

namespace imubridge::diagnose::report_parts {

// A finite number, or null (JSON has no NaN or infinity).
nlohmann::json number(double value);
// The name of axis `index` of the diagnosis, or its index when it has none.
std::string axis_name(const Diagnosis& d, std::size_t index);
// The residual analysis of `axis`, or null when that axis was not analysed.
const ResidualAnalysis* analysis_for(const Diagnosis& d, const std::vector<ResidualAnalysis>& residuals,
                                     const std::string& axis);
std::string join(const std::vector<std::string>& items, std::string_view separator);
// `text` as the whole of `file`, or nothing (fileio::write_whole_file). Throws std::runtime_error when it cannot
// be written.
void write_text(const std::filesystem::path& file, const std::string& text);

// The figure's title and caption are the page's (plain text, escaped there), so the legend can sit on top.
struct Plot {
  GnuplotFigure figure;
  std::string group;  // heading it appears under
  std::string title;
  std::string caption;
};

// The report's figures, and in `data` the files of numbers their gnuplot commands read.
std::vector<Plot> make_plots(const Diagnosis& d, std::map<std::string, std::string>& data);

}  // namespace imubridge::diagnose::report_parts
