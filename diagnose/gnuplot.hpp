#pragma once
// Figures drawn by gnuplot (Debian package gnuplot-nox) with its SVG terminal, returned as SVG elements ready to
// inline into one self-contained HTML page. gnuplot runs as a subprocess on data files written to a scratch
// directory that is removed afterwards; when it is missing or fails, the caller gets the reason instead of figures.
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace imubridge::diagnose {

struct GnuplotFigure {
  std::string name;  // unique among the figures, letters, digits and '_': the SVG file's stem and its ids' prefix
  int width = 1000, height = 320;  // px
  std::string commands;  // gnuplot commands that draw it (after terminal and output are set), reading data by name
};

struct GnuplotResult {
  std::vector<std::string> svgs;  // one <svg> element per figure, in order; empty when `error` is set
  std::string error;              // one line: why there are no figures (empty on success)
};

// Renders every figure in one gnuplot run. `data_files` maps a file name (no directories) to its content.
GnuplotResult render_svg_figures(const std::vector<GnuplotFigure>& figures,
                                 const std::map<std::string, std::string>& data_files);

// The executable `name` in a PATH directory, if any.
std::optional<std::filesystem::path> find_on_path(std::string_view name);

// `text` as a gnuplot single-quoted string literal.
std::string gnuplot_quote(std::string_view text);

// gnuplot's SVG file as an element to inline: the XML prolog dropped, and every id (and reference to one) prefixed
// with `id_prefix`, because all figures share the ids of gnuplot's point symbols and one page must not repeat ids.
std::string inline_svg(std::string_view svg_file, std::string_view id_prefix);

}  // namespace imubridge::diagnose
