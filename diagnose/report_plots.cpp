// The report's figures as gnuplot commands and data: measured vs model, the residual, its spectrum, convergence.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <map>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "diagnose/report_parts.hpp"

namespace imubridge::diagnose::report_parts {
namespace {

using nlohmann::json;

constexpr double kExcerptSeconds = 10.0;      // the measured-vs-model figure shows this much when the window is long
constexpr std::size_t kMaxPlotPoints = 2400;  // per curve: about two per horizontal pixel of a 1000 px figure

// Okabe-Ito colours: distinguishable with the common colour-vision deficiencies.
constexpr std::string_view kMeasuredColour = "#A0A0A0", kBaseColour = "#E69F00", kFinalColour = "#0072B2",
                           kMarkColour = "#D55E00";

using Curve = std::vector<std::pair<double, double>>;

// At most max_points points that keep the curve's look: beyond that, each bucket of samples contributes its minimum
// and its maximum, in time order, so peaks and the noise band survive the thinning.
Curve envelope(std::span<const double> t, std::span<const double> y, std::size_t max_points) {
  Curve curve;
  const std::size_t n = std::min(t.size(), y.size());
  if (n <= max_points) {
    for (std::size_t i = 0; i < n; ++i) curve.emplace_back(t[i], y[i]);
    return curve;
  }
  const std::size_t buckets = max_points / 2;
  for (std::size_t b = 0; b < buckets; ++b) {
    const std::size_t first = b * n / buckets, last = (b + 1) * n / buckets;
    std::size_t low = first, high = first;
    for (std::size_t i = first; i < last; ++i) {
      if (y[i] < y[low]) low = i;
      if (y[i] > y[high]) high = i;
    }
    curve.emplace_back(t[std::min(low, high)], y[std::min(low, high)]);
    if (low != high) curve.emplace_back(t[std::max(low, high)], y[std::max(low, high)]);
  }
  return curve;
}

void append_number(std::string& out, double value) {
  if (!std::isfinite(value)) {
    out += "NaN";  // gnuplot leaves the point out
    return;
  }
  char buffer[32];
  const auto end = std::to_chars(buffer, buffer + sizeof buffer, value).ptr;  // shortest exact, locale-free
  out.append(buffer, end);
}

// gnuplot data: one block per curve, blocks separated by two blank lines (selected with `index`).
std::string data_blocks(const std::vector<Curve>& curves) {
  std::string out;
  for (const auto& curve : curves) {
    for (const auto& [x, y] : curve) {
      append_number(out, x);
      out += ' ';
      append_number(out, y);
      out += '\n';
    }
    out += "\n\n";
  }
  return out;
}

// The span of about `seconds` with the most variance in `y` (where the vehicle manoeuvres: the model has the most to
// explain there); the whole series when it is not much longer. Returns [first, last) indices.
std::pair<std::size_t, std::size_t> most_active_span(std::span<const double> t, std::span<const double> y,
                                                     double seconds) {
  const std::size_t n = y.size();
  if (n == 0 || t.back() - t.front() <= 1.2 * seconds) return {0, n};
  std::vector<double> sum(n + 1, 0.0), sum_sq(n + 1, 0.0);
  const double offset = y[0];  // sums of y - y[0] keep the variance's cancellation small
  for (std::size_t i = 0; i < n; ++i) {
    sum[i + 1] = sum[i] + (y[i] - offset);
    sum_sq[i + 1] = sum_sq[i] + (y[i] - offset) * (y[i] - offset);
  }
  std::pair<std::size_t, std::size_t> best{0, n};
  double best_variance = -1.0;
  std::size_t end = 0;
  for (std::size_t first = 0; first < n; ++first) {
    while (end < n && t[end] < t[first] + seconds) ++end;
    if (t[first] + seconds > t.back()) break;  // a span cut short by the end of the data is not an excerpt
    const double count = static_cast<double>(end - first);
    const double mean = (sum[end] - sum[first]) / count;
    const double variance = (sum_sq[end] - sum_sq[first]) / count - mean * mean;
    if (variance > best_variance) {
      best_variance = variance;
      best = {first, end};
    }
  }
  return best;
}

std::vector<double> difference(std::span<const double> a, std::span<const double> b) {
  std::vector<double> out(std::min(a.size(), b.size()));
  for (std::size_t i = 0; i < out.size(); ++i) out[i] = a[i] - b[i];
  return out;
}

std::string fixed(double value, int decimals) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.*f", decimals, value);
  return buffer;
}

std::string quote(std::string_view text) { return gnuplot_quote(text); }

std::string line_style(std::string_view colour, double width) {
  return "with lines lc rgb " + quote(colour) + " lw " + fixed(width, 1);
}

struct Line {
  Curve points;
  std::string style;  // gnuplot's `using ... with ...`
  std::string title;  // empty: not in the legend
};

// The `plot` command drawing `lines` from `file`, whose content (one block per line) goes into `data`. Lines without
// points are left out: gnuplot stops at a plot with no valid points, and would take every figure with it.
std::string plot_lines(const std::string& file, const std::vector<Line>& lines,
                       std::map<std::string, std::string>& data) {
  std::vector<Curve> blocks;
  std::string command = "plot";
  for (const auto& line : lines) {
    if (line.points.empty()) continue;
    command += std::string(blocks.empty() ? " " : ", ") + quote(file) + " index " + std::to_string(blocks.size()) +
               " " + line.style + (line.title.empty() ? " notitle" : " title " + quote(line.title));
    blocks.push_back(line.points);
  }
  data[file] = data_blocks(blocks);
  return command + "\n";
}

constexpr std::string_view kCommonSettings =
    "set grid lc rgb '#dddddd'\nset border lc rgb '#555555'\nset key outside top center horizontal\n"
    "set offsets 0, 0, graph 0.05, graph 0.05\n";
// Time runs from the first sample to the last, without gnuplot's rounding out to the next tic.
constexpr std::string_view kTimeAxis = "set autoscale xfix\nset xlabel 'time (s)'\n";



std::string final_model_words(const Diagnosis& d) {
  if (d.final.effects.empty()) return "the final model (the base model: no effect was added)";
  std::string words = "the final model (base";
  for (const auto& effect : d.final.effects) words += " + " + effect;
  return words + ")";
}

// Measured vs base vs final over (an excerpt of) the validation window: the paper's Fig. 13 before and after.
void add_fit_plot(const Diagnosis& d, const AxisSeries& s, std::size_t n, const std::string& id,
                  std::vector<Plot>& plots, std::map<std::string, std::string>& data) {
  const std::span<const double> t(s.t.data(), n);
  const auto [first, last] = most_active_span(t, std::span(s.measured.data(), n), kExcerptSeconds);
  if (last - first < 2) return;
  const auto cut = [&](const std::vector<double>& v) { return std::span(v.data() + first, last - first); };
  const auto tt = cut(s.t);
  const bool excerpt = first > 0 || last < n;
  const std::string span = fixed(tt.front(), 1) + "–" + fixed(tt.back(), 1) + " s";
  std::string commands(kCommonSettings);
  commands += kTimeAxis;
  commands += "set ylabel 'specific force (m/s²)'\n";
  commands +=
      plot_lines(id + "_fit.dat",
                 {{envelope(tt, cut(s.measured), kMaxPlotPoints), line_style(kMeasuredColour, 2.0), "measured"},
                  {envelope(tt, cut(s.base_model), kMaxPlotPoints), line_style(kBaseColour, 1.2), "base model"},
                  {envelope(tt, cut(s.final_model), kMaxPlotPoints), line_style(kFinalColour, 1.0), "final model"}},
                 data);
  plots.push_back(
      {{id + "_fit", 1000, 340, commands},
       "Axis " + s.axis,
       "Axis " + s.axis + ": measured vs model, validation " + span,
       std::string(excerpt ? "The 10 s of the validation window with the most motion" : "The validation window") +
           " (" + span + "): measured specific force, the base model, and " + final_model_words(d) +
           ". The paper's Fig. 13, before and after."});
}

// measured - model over the whole validation window, before and after the search.
void add_residual_plot(const AxisSeries& s, std::size_t n, const std::string& id, std::vector<Plot>& plots,
                       std::map<std::string, std::string>& data) {
  const std::span<const double> t(s.t.data(), n), measured(s.measured.data(), n);
  const auto before = difference(measured, std::span(s.base_model.data(), n));
  const auto after = difference(measured, std::span(s.final_model.data(), n));
  std::string commands(kCommonSettings);
  commands += kTimeAxis;
  commands += "set ylabel 'residual (m/s²)'\n";
  commands += plot_lines(id + "_residual.dat",
                         {{envelope(t, before, kMaxPlotPoints), line_style(kBaseColour, 1.0), "before (base model)"},
                          {envelope(t, after, kMaxPlotPoints), line_style(kFinalColour, 1.0), "after (final model)"}},
                         data);
  plots.push_back({{id + "_residual", 1000, 300, commands},
                   "Axis " + s.axis,
                   "Axis " + s.axis + ": residual (measured − model), validation window",
                   "Residual over the whole validation window. Where a window holds more samples than the figure "
                   "has pixels, each pixel column shows its samples' minimum and maximum."});
}

// Welch spectra of the validation residual before and after, log power, with the unexplained lines marked.
void add_spectrum_plot(const Diagnosis& d, const std::string& axis, const std::string& id, std::vector<Plot>& plots,
                       std::map<std::string, std::string>& data) {
  const ResidualAnalysis* before = analysis_for(d, d.base_residual, axis);
  const ResidualAnalysis* after = analysis_for(d, d.final_residual, axis);
  const auto spectrum = [](const ResidualAnalysis* r) {
    Curve curve;
    if (r == nullptr) return curve;
    for (std::size_t i = 0; i < r->frequency_hz.size() && i < r->psd.size(); ++i) {
      if (r->psd[i] > 0.0) curve.emplace_back(r->frequency_hz[i], r->psd[i]);  // log axis: no zeros
    }
    return curve;
  };
  const Curve before_curve = spectrum(before), after_curve = spectrum(after);
  if (before_curve.empty() && after_curve.empty()) return;
  Curve marks;  // each unexplained line at the final spectrum's height there
  for (const auto& u : d.unexplained) {
    if (u.axis != axis || u.kind != "frequency" || after_curve.empty()) continue;
    const auto nearest = std::min_element(after_curve.begin(), after_curve.end(), [&](const auto& a, const auto& b) {
      return std::abs(a.first - u.frequency_hz) < std::abs(b.first - u.frequency_hz);
    });
    marks.emplace_back(u.frequency_hz, nearest->second);
  }
  std::string commands(kCommonSettings);
  commands += "set xlabel 'frequency (Hz)'\nset ylabel 'PSD ((m/s²)²/Hz)'\n";
  commands += "set logscale y\nset format y '%.0e'\nset offsets 0, 0, 0, 0\n";  // log autoscale pads to a decade
  const std::string mark_colour = quote(kMarkColour);
  commands +=
      plot_lines(id + "_spectrum.dat",
                 {{before_curve, line_style(kBaseColour, 1.2), "before (base model)"},
                  {after_curve, line_style(kFinalColour, 1.2), "after (final model)"},
                  {marks, "with points pt 7 ps 1.2 lc rgb " + mark_colour, "unexplained line"},
                  {marks, "using 1:2:(sprintf('%.1f Hz', $1)) with labels offset 0,1 tc rgb " + mark_colour, ""}},
                 data);
  plots.push_back({{id + "_spectrum", 1000, 300, commands},
                   "Axis " + axis,
                   "Axis " + axis + ": residual spectrum, validation window",
                   "Power spectral density of the validation residual (Welch). A line standing far above its "
                   "neighbours is a periodic component the model does not explain."});
}

// Cost after each solver iteration, for the base fit and the refit at each step (the paper's Fig. 12).
void add_convergence_plot(const Diagnosis& d, std::vector<Plot>& plots, std::map<std::string, std::string>& data) {
  std::vector<Line> lines;
  const auto add = [&](const std::vector<double>& costs, std::string title) {
    Curve curve;
    for (std::size_t i = 0; i < costs.size(); ++i) curve.emplace_back(static_cast<double>(i), costs[i]);
    lines.push_back({std::move(curve), "with linespoints pt 7 ps 0.5 lw 1.5", std::move(title)});
  };
  add(d.base.convergence, "base");
  for (const auto& step : d.steps) add(step.fit.convergence, "+ " + step.effect);
  std::size_t iterations = 0;
  for (const auto& line : lines) iterations = std::max(iterations, line.points.size());
  if (iterations == 0) return;
  const bool positive = std::all_of(lines.begin(), lines.end(), [](const Line& line) {
    return std::all_of(line.points.begin(), line.points.end(),
                       [](const auto& p) { return !std::isfinite(p.second) || p.second > 0.0; });
  });
  std::string commands(kCommonSettings);
  commands += "set xlabel 'solver iteration'\nset ylabel 'cost'\nset autoscale xfix\n";
  commands += "set xtics " + std::to_string(std::max<std::size_t>(1, (iterations + 9) / 10)) + "\n";  // whole numbers
  if (positive) commands += "set logscale y\nset offsets 0, 0, 0, 0\n";  // log autoscale already pads to a decade
  commands += plot_lines("convergence.dat", lines, data);
  plots.push_back({{"convergence", 1000, 320, commands},
                   "Convergence of the fits",
                   "Cost after each iteration of each fit",
                   "Cost (square root of the sum of squared residuals, training window) after each "
                   "Levenberg–Marquardt iteration: the base model's fit and the refit of everything after each step "
                   "(the paper's Fig. 12)."});
}


// ================================================ report.html ================================================

}  // namespace

std::vector<Plot> make_plots(const Diagnosis& d, std::map<std::string, std::string>& data) {
  std::vector<Plot> plots;
  std::vector<std::string> axes_plotted;
  for (std::size_t i = 0; i < d.series.size(); ++i) {
    const auto& s = d.series[i];
    const std::size_t n = std::min({s.t.size(), s.measured.size(), s.base_model.size(), s.final_model.size()});
    const std::string id = "axis" + std::to_string(i);
    if (n >= 2) {
      add_fit_plot(d, s, n, id, plots, data);
      add_residual_plot(s, n, id, plots, data);
    }
    add_spectrum_plot(d, s.axis, id, plots, data);
    axes_plotted.push_back(s.axis);
  }
  for (std::size_t i = 0; i < d.axes.size(); ++i) {  // axes analysed without series: their spectra still show
    if (std::find(axes_plotted.begin(), axes_plotted.end(), d.axes[i]) != axes_plotted.end()) continue;
    add_spectrum_plot(d, d.axes[i], "spectrum" + std::to_string(i), plots, data);
  }
  add_convergence_plot(d, plots, data);
  return plots;
}

}  // namespace imubridge::diagnose::report_parts
