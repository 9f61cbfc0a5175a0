#include "diagnose/report.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "diagnose/gnuplot.hpp"

namespace imubridge::diagnose {
namespace {

using nlohmann::json;

// ================================================ report.json ================================================

json number(double value) { return std::isfinite(value) ? json(value) : json(nullptr); }

json numbers(const std::vector<double>& values) {
  json list = json::array();
  for (double v : values) list.push_back(number(v));
  return list;
}

std::string axis_name(const Diagnosis& d, std::size_t index) {
  return index < d.axes.size() ? d.axes[index] : std::to_string(index);
}

json parameter_json(const ParameterEstimate& p) {
  return {{"name", p.name}, {"value", number(p.value)}, {"std_error", number(p.std_error)}, {"unit", p.unit}};
}

json parameters_json(const std::vector<ParameterEstimate>& params) {
  json list = json::array();
  for (const auto& p : params) list.push_back(parameter_json(p));
  return list;
}

// A fit's parameters in one list, each saying which part of the model it belongs to ("base" or the effect).
json fit_parameters_json(const ModelFit& fit) {
  json list = json::array();
  const auto add = [&](const std::vector<ParameterEstimate>& params, const std::string& component) {
    for (const auto& p : params) {
      json entry = parameter_json(p);
      entry["component"] = component;
      list.push_back(std::move(entry));
    }
  };
  add(fit.base_params, "base");
  for (std::size_t i = 0; i < fit.effects.size() && i < fit.effect_params.size(); ++i) {
    add(fit.effect_params[i], fit.effects[i]);
  }
  return list;
}

json score_json(const estimator::VelocityError& s) {
  return {{"x", number(s.axis.x())}, {"y", number(s.axis.y())}, {"horizontal", number(s.horizontal)}};
}

json velocity_json(const std::optional<estimator::VelocityScores>& v) {
  if (!v) return nullptr;
  json out = {{"train", score_json(v->train)}, {"validation", score_json(v->validation)}};
  if (!v->note.empty()) out["note"] = v->note;
  return out;
}

json model_json(const ModelFit& fit) {
  return {{"effects", fit.effects},
          {"params", fit_parameters_json(fit)},
          {"free_parameters", fit.free_parameters},
          {"velocity_rmse_m_s", velocity_json(fit.velocity)},
          {"at_bounds", fit.at_bounds},
          {"implausible", fit.implausible},
          {"convergence", numbers(fit.convergence)}};
}

json residual_json(const ResidualAnalysis& r, const std::string& axis) {
  json peaks = json::array();
  for (std::size_t i = 0; i < r.peaks.size() && i < kReportTopEntries; ++i) {
    const auto& peak = r.peaks[i];
    peaks.push_back({{"frequency_hz", number(peak.frequency_hz)},
                     {"power_ratio", number(peak.power_ratio)},
                     {"ignored", peak.ignored}});
  }
  json correlations = json::array();
  std::size_t significant = 0;
  for (std::size_t i = 0; i < r.correlations.size(); ++i) {
    const auto& c = r.correlations[i];
    significant += c.significant ? 1 : 0;
    if (i >= kReportTopEntries) continue;
    correlations.push_back({{"signal", c.signal},
                            {"lag_s", number(c.lag_s)},
                            {"coefficient", number(c.coefficient)},
                            {"threshold", number(c.threshold)},
                            {"significant", c.significant}});
  }
  return {
      {"axis", axis},
      {"samples", r.samples},
      {"rms", number(r.rms)},
      {"mean", number(r.mean)},
      {"ljung_box",
       {{"lags", r.ljung_box_lags}, {"q", number(r.ljung_box_q)}, {"p", number(r.ljung_box_p)}, {"white", r.white}}},
      {"peaks", std::move(peaks)},
      {"peaks_found", r.peaks.size()},
      {"correlations", std::move(correlations)},
      {"significant_correlations", significant},
      {"trend",
       {{"per_s", number(r.trend_per_s)},
        {"std_error", number(r.trend_std_error)},
        {"significant", r.trend_significant}}}};
}

json residuals_json(const Diagnosis& d, const std::vector<ResidualAnalysis>& residuals) {
  json list = json::array();
  for (std::size_t i = 0; i < residuals.size(); ++i) list.push_back(residual_json(residuals[i], axis_name(d, i)));
  return list;
}

// Every axis white; null when there is no analysis to judge by.
json whiteness(const std::vector<ResidualAnalysis>& residuals) {
  if (residuals.empty()) return nullptr;
  return std::all_of(residuals.begin(), residuals.end(), [](const ResidualAnalysis& r) { return r.white; });
}

// base and final: the fit's fields directly, with its residual.
json fit_json(const Diagnosis& d, const ModelFit& fit, const std::vector<ResidualAnalysis>& residual) {
  json out = model_json(fit);
  out["rmse_train"] = number(fit.rmse_train);
  out["rmse_validation"] = number(fit.rmse_validation);
  out["velocity_rmse_m_s"] = velocity_json(fit.velocity);
  out["residual"] = residuals_json(d, residual);
  out["residual_white"] = whiteness(residual);
  return out;
}

json candidates_json(const std::vector<CandidateTrial>& candidates) {
  json list = json::array();
  for (const auto& c : candidates) {
    list.push_back({{"effect", c.effect},
                    {"with", c.with},
                    {"rmse_train", number(c.rmse_train)},
                    {"rmse_validation", number(c.rmse_validation)},
                    {"statistic", number(c.statistic)},
                    {"p_value", number(c.p_value)},
                    {"significant", c.significant},
                    {"rejected_by", c.rejected_by},
                    {"skipped", c.skipped}});
  }
  return list;
}

json step_json(const Diagnosis& d, const Step& step) {
  return {{"effect", step.effect},
          {"with", step.with},
          {"params", parameters_json(step.params)},
          {"rmse_train", number(step.fit.rmse_train)},
          {"rmse_validation", number(step.fit.rmse_validation)},
          {"rmse_train_before", number(step.rmse_train_before)},
          {"rmse_validation_before", number(step.rmse_validation_before)},
          {"velocity_rmse_m_s", velocity_json(step.fit.velocity)},
          {"residual_white", whiteness(step.residual)},
          {"residual", residuals_json(d, step.residual)},
          {"candidates", candidates_json(step.candidates)},
          {"model", model_json(step.fit)}};
}

json unexplained_json(const Unexplained& u) {
  json out = {{"kind", u.kind}, {"axis", u.axis}, {"where", u.where}, {"value", number(u.value)}};
  if (u.kind == "frequency") out["frequency_hz"] = number(u.frequency_hz);
  if (u.kind == "correlation") out["signal"] = u.signal;
  if (u.kind == "correlation" || u.kind == "autocorrelation") out["lag_s"] = number(u.lag_s);
  return out;
}

// ================================================ plots ================================================

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

// The figure's title and caption are the page's (plain text, escaped there), so the legend can sit on top.
struct Plot {
  GnuplotFigure figure;
  std::string group;  // heading it appears under
  std::string title;
  std::string caption;
};

const ResidualAnalysis* analysis_for(const Diagnosis& d, const std::vector<ResidualAnalysis>& residuals,
                                     const std::string& axis) {
  for (std::size_t i = 0; i < residuals.size() && i < d.axes.size(); ++i) {
    if (d.axes[i] == axis) return &residuals[i];
  }
  return nullptr;
}

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

// ================================================ report.html ================================================

std::string escape(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&#39;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

// Significant digits for people; "n/a" for what could not be computed.
std::string num(double value, int digits = 4) {
  if (!std::isfinite(value)) return "n/a";
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.*g", digits, value);
  return buffer;
}

// A p-value for people: tiny ones (which print as 0 or 1e-300) all mean the same thing to a reader.
std::string p_value(double p) { return std::isfinite(p) && p < 1e-6 ? "< 1e-6" : num(p, 2); }
// "p = 0.03", "p < 1e-6"
std::string p_clause(double p) {
  const std::string value = p_value(p);
  return value.front() == '<' ? "p " + value : "p = " + value;
}

std::string signed_num(double value, int digits = 3) { return (value >= 0.0 ? "+" : "") + num(value, digits); }

std::string percent_change(double before, double after) {
  if (!std::isfinite(before) || !std::isfinite(after) || before == 0.0) return "";
  return signed_num(100.0 * (after - before) / before, 3) + " %";
}

std::string join(const std::vector<std::string>& items, std::string_view separator) {
  std::string out;
  for (const auto& item : items) out += (out.empty() ? "" : std::string(separator)) + item;
  return out;
}

std::string window_text(double start, double end) {
  return num(start, 6) + " – " + num(end, 6) + " s (" + num(end - start, 4) + " s)";
}

std::string parameter_text(const ParameterEstimate& p) {
  std::string text = escape(p.name) + " = " + num(p.value) + " ± " + num(p.std_error, 2);
  if (!p.unit.empty()) text += " " + escape(p.unit);
  return "<span class=\"nw\">" + text + "</span>";
}

std::string parameters_cell(const std::vector<ParameterEstimate>& params) {
  std::string cell;
  for (const auto& p : params) cell += (cell.empty() ? "" : "<br>") + parameter_text(p);
  return cell.empty() ? "—" : cell;
}

std::string whiteness_cell(const Diagnosis& d, const std::vector<ResidualAnalysis>& residuals) {
  if (residuals.empty()) return "—";
  std::string cell;
  for (std::size_t i = 0; i < residuals.size(); ++i) {
    const auto& r = residuals[i];
    cell += std::string(i == 0 ? "" : "<br>") + "<span class=\"nw\"><span class=\"" + (r.white ? "white" : "notwhite") +
            "\">" + escape(axis_name(d, i)) + ": " + (r.white ? "white" : "not white") + "</span> (" +
            p_clause(r.ljung_box_p) + ")</span>";
  }
  return cell;
}

std::string kind_words(const std::string& kind) {
  if (kind == "frequency") return "periodic component";
  if (kind == "correlation") return "correlation with a measured signal";
  if (kind == "trend") return "trend over time";
  if (kind == "autocorrelation") return "self-correlation";
  return kind;
}

class Page {
 public:
  void add(std::string_view html) { html_ += html; }
  void heading(int level, std::string_view text) {
    const std::string tag = "h" + std::to_string(level);
    html_ += "<" + tag + ">" + escape(text) + "</" + tag + ">\n";
  }
  void paragraph(std::string_view text, std::string_view css_class = {}) {
    html_ += css_class.empty() ? "<p>" : "<p class=\"" + std::string(css_class) + "\">";
    html_ += escape(text) + "</p>\n";
  }
  // Cells are HTML already (escape() what comes from the data).
  void table(const std::vector<std::string>& header, const std::vector<std::vector<std::string>>& rows,
             const std::vector<std::string>& row_classes = {}, std::string_view css_class = {}) {
    // The wrapper scrolls a table wider than the page instead of letting it spill over the margin.
    html_ += "<div class=\"scroll\">";
    html_ += css_class.empty() ? "<table>\n" : "<table class=\"" + std::string(css_class) + "\">\n";
    if (!header.empty()) {
      html_ += "<tr>";
      for (const auto& h : header) html_ += "<th>" + escape(h) + "</th>";
      html_ += "</tr>\n";
    }
    for (std::size_t r = 0; r < rows.size(); ++r) {
      const bool marked = r < row_classes.size() && !row_classes[r].empty();
      html_ += marked ? "<tr class=\"" + row_classes[r] + "\">" : std::string("<tr>");
      for (const auto& cell : rows[r]) html_ += "<td>" + cell + "</td>";
      html_ += "</tr>\n";
    }
    html_ += "</table></div>\n";
  }
  const std::string& html() const { return html_; }

 private:
  std::string html_;
};

constexpr std::string_view kStyle = R"(
body{font-family:"DejaVu Sans",system-ui,-apple-system,"Segoe UI",sans-serif;max-width:1180px;margin:0 auto;
  padding:24px;color:#222;line-height:1.45;font-size:15px}
h1{font-size:1.7em;margin:0 0 4px}
h2{font-size:1.3em;border-bottom:1px solid #ccc;padding-bottom:4px;margin-top:2em}
h3{font-size:1.1em;margin-top:1.5em}
.scroll{overflow-x:auto}td:first-child{white-space:nowrap}
table{border-collapse:collapse;margin:8px 0 16px;font-size:14px}
th,td{border:1px solid #d6d6d6;padding:4px 8px;text-align:left;vertical-align:top}
th{background:#f2f2f2;font-weight:600}
tr.chosen td{background:#eaf4ea}
tr.final td{background:#eef3fb;font-weight:600}
.banner{padding:12px 16px;border-radius:6px;margin:16px 0}
.banner strong{font-size:1.1em}
.banner ul{margin:6px 0 0}
.bad{background:#fdecea;border:2px solid #c5221f;color:#8c1d18}
.good{background:#e6f4ea;border:2px solid #188038;color:#0d652d}
.note{color:#666;font-style:italic}
.nw{white-space:nowrap}table.nowrap td{white-space:nowrap}table.nowrap td:last-child{white-space:normal}
.white{color:#188038}.notwhite{color:#c5221f;font-weight:600}
figure{margin:20px 0}.figtitle{font-weight:600;margin-bottom:2px}figcaption{color:#555;font-size:.9em;margin-top:2px}
svg{max-width:100%;height:auto;display:block}
)";

void summary_section(const Diagnosis& d, Page& page) {
  page.heading(2, "Summary");
  std::string result;
  if (d.steps.empty()) {
    result = "no effect added: no candidate passed the significance rule";
  } else {
    std::vector<std::string> effects;
    for (const auto& step : d.steps) effects.push_back(escape(with_needed(step.effect, step.with)));
    result = std::to_string(d.steps.size()) + (d.steps.size() == 1 ? " effect" : " effects") + " added (" +
             join(effects, ", ") + "); validation RMSE " + num(d.base.rmse_validation) + " → " +
             num(d.final.rmse_validation) + " m/s² (" +
             percent_change(d.base.rmse_validation, d.final.rmse_validation) + ")";
  }
  page.table({}, {{"Session", escape(d.session)},
                  {"Base model", escape(d.model)},
                  {"Axes", escape(join(d.axes, ", "))},
                  {"IMU axes", escape(d.imu_axes)},
                  {"Velocity source", escape(d.velocity_source)},
                  {"Training window", window_text(d.train_start, d.train_end)},
                  {"Validation window", window_text(d.validate_start, d.validate_end)},
                  {"Significance rule", escape(d.significance_rule)},
                  {"Result", result},
                  {"Velocity", escape(summary_line(d))}});
  std::vector<std::string> flags = d.warnings;
  for (const ModelFit* fit : {&d.base, &d.final}) {
    const std::string which = fit == &d.base ? "base: " : "final: ";
    for (const auto& b : fit->at_bounds) flags.push_back(which + b);
    for (const auto& b : fit->implausible) flags.push_back(which + "implausible: " + b);
  }
  if (!flags.empty()) {
    page.add("<div class=\"banner bad\"><strong>Check these</strong><ul>");
    for (const auto& f : flags) page.add("<li>" + escape(f) + "</li>");
    page.add("</ul></div>\n");
  }
}

void banner(const Diagnosis& d, Page& page) {
  if (d.residual_white) {
    page.add(
        "<div class=\"banner good\"><strong>The residual is white</strong> on every axis (Ljung–Box on the "
        "validation window): no structure is left that the analysis can find.</div>\n");
    return;
  }
  page.add(
      "<div class=\"banner bad\"><strong>The residual is not white</strong>: structure remains that the final "
      "model does not explain.");
  if (d.unexplained.empty()) {
    page.add(" The analysis located no particular line, correlation or trend.");
  } else {
    page.add("<ul>");
    for (const auto& u : d.unexplained) {
      page.add("<li>axis " + escape(u.axis) + ", " + escape(kind_words(u.kind)) + ": " + escape(u.where) + "</li>");
    }
    page.add("</ul>");
  }
  page.add("</div>\n");
}

void search_section(const Diagnosis& d, Page& page) {
  page.heading(2, "Model search");
  page.paragraph(
      "Each step adds the effect that lowers the validation error most, then refits everything. RMSE is "
      "over the axes diagnosed, in m/s²; whiteness is the Ljung–Box test on the validation residual.");
  std::vector<std::vector<std::string>> rows;
  std::vector<std::string> classes;
  const auto velocity = [](const ModelFit& fit, bool validation) -> std::string {
    if (!fit.velocity) return "";
    const estimator::VelocityError& s = validation ? fit.velocity->validation : fit.velocity->train;
    return num(s.horizontal, 3) + " (" + num(s.axis.x(), 3) + ", " + num(s.axis.y(), 3) + ")" +
           (fit.velocity->note.empty() ? "" : " *");
  };
  rows.push_back({"0", "base model (" + escape(d.model) + ")", parameters_cell(d.base.base_params),
                  std::to_string(d.base.free_parameters), num(d.base.rmse_train), num(d.base.rmse_validation), "",
                  velocity(d.base, false), velocity(d.base, true), whiteness_cell(d, d.base_residual)});
  classes.emplace_back();
  for (std::size_t i = 0; i < d.steps.size(); ++i) {
    const auto& step = d.steps[i];
    rows.push_back({std::to_string(i + 1), "+ " + escape(with_needed(step.effect, step.with)),
                    parameters_cell(step.params), std::to_string(step.fit.free_parameters), num(step.fit.rmse_train),
                    num(step.fit.rmse_validation),
                    percent_change(step.rmse_validation_before, step.fit.rmse_validation), velocity(step.fit, false),
                    velocity(step.fit, true), whiteness_cell(d, step.residual)});
    classes.emplace_back();
  }
  std::vector<std::string> model{"base model"};
  for (const auto& effect : d.final.effects) model.push_back("<span class=\"nw\">+ " + escape(effect) + "</span>");
  rows.push_back({"final", join(model, "<br>"), "see Final model parameters", std::to_string(d.final.free_parameters),
                  num(d.final.rmse_train), num(d.final.rmse_validation),
                  percent_change(d.base.rmse_validation, d.final.rmse_validation), velocity(d.final, false),
                  velocity(d.final, true), whiteness_cell(d, d.final_residual)});
  classes.emplace_back("final");
  page.table({"Step", "Model", "Parameters added (± standard error)", "Free params", "RMSE train", "RMSE validation",
              "Δ validation", "Velocity RMSE train (m/s)", "Velocity RMSE validation (m/s)", "Residual"},
             rows, classes);
  if (d.zero_velocity) {
    page.paragraph(
        "Velocity RMSE: the drag-velocity estimator run with each step's model (horizontal (x, y), against "
        "the reference; zero velocity scores " +
            num(d.zero_velocity->train.horizontal, 3) + " on the training and " +
            num(d.zero_velocity->validation.horizontal, 3) +
            " m/s on the validation window). * a model without a drag law on an axis gives no velocity: "
            "scored as zero velocity.",
        "note");
  }
}

void unexplained_section(const Diagnosis& d, Page& page) {
  page.heading(2, "Unexplained structure");
  if (d.unexplained.empty()) {
    page.paragraph(d.residual_white ? "None: the final residual is white on every axis."
                                    : "The final residual is not white, but the analysis located no particular "
                                      "spectral line, correlated signal or trend.");
    return;
  }
  std::vector<std::vector<std::string>> rows;
  for (const auto& u : d.unexplained) rows.push_back({escape(u.axis), escape(kind_words(u.kind)), escape(u.where)});
  page.paragraph("Structure left in the final validation residual that no effect of the library took away:");
  page.table({"Axis", "Kind", "Where"}, rows);
}

void parameters_section(const Diagnosis& d, Page& page) {
  page.heading(2, "Final model parameters");
  std::vector<std::vector<std::string>> rows;
  const auto add = [&](const std::vector<ParameterEstimate>& params, const std::string& component) {
    for (const auto& p : params) {
      rows.push_back({escape(component), escape(p.name), num(p.value, 6), num(p.std_error, 2), escape(p.unit)});
    }
  };
  add(d.final.base_params, "base");
  for (std::size_t i = 0; i < d.final.effects.size() && i < d.final.effect_params.size(); ++i) {
    add(d.final.effect_params[i], d.final.effects[i]);
  }
  page.table({"Component", "Parameter", "Value", "Standard error", "Unit"}, rows);
}

std::string peaks_text(const ResidualAnalysis& r) {
  std::string text;
  for (std::size_t i = 0; i < r.peaks.size() && i < kReportTopEntries; ++i) {
    const auto& p = r.peaks[i];
    text += (text.empty() ? "" : "<br>") + num(p.frequency_hz) + " Hz (" + num(p.power_ratio, 3) + "× median)" +
            (p.ignored ? " ignored" : "");
  }
  return text.empty() ? "none" : text;
}

std::string correlations_text(const ResidualAnalysis& r) {
  std::string text;
  for (std::size_t i = 0; i < r.correlations.size() && i < kReportTopEntries; ++i) {
    const auto& c = r.correlations[i];
    text += (text.empty() ? "" : "<br>") + escape(c.signal) + " at " + signed_num(c.lag_s) +
            " s: r = " + num(c.coefficient, 2) + (c.significant ? " <b>significant</b>" : "") + " (threshold " +
            num(c.threshold, 2) + ")";
  }
  return text.empty() ? "none" : text;
}

void residual_section(const Diagnosis& d, Page& page) {
  page.heading(2, "Residual analysis (validation window)");
  for (std::size_t i = 0; i < d.axes.size(); ++i) {
    const ResidualAnalysis* before = analysis_for(d, d.base_residual, d.axes[i]);
    const ResidualAnalysis* after = analysis_for(d, d.final_residual, d.axes[i]);
    if (before == nullptr && after == nullptr) continue;
    const auto column = [](const ResidualAnalysis* r, auto describe) { return r == nullptr ? "—" : describe(*r); };
    const auto row = [&](std::string label, auto describe) {
      return std::vector<std::string>{std::move(label), column(before, describe), column(after, describe)};
    };
    page.heading(3, "Axis " + d.axes[i]);
    page.table({"", "Base model", "Final model"},
               {row("Samples", [](const ResidualAnalysis& r) { return std::to_string(r.samples); }),
                row("RMS (m/s²)", [](const ResidualAnalysis& r) { return num(r.rms); }),
                row("Mean (m/s²)", [](const ResidualAnalysis& r) { return num(r.mean, 3); }),
                row("Ljung–Box",
                    [](const ResidualAnalysis& r) {
                      return "Q = " + num(r.ljung_box_q) + " over " + std::to_string(r.ljung_box_lags) + " lags, " +
                             p_clause(r.ljung_box_p) + ": <span class=\"" +
                             (r.white ? "white\">white" : "notwhite\">not white") + "</span>";
                    }),
                row("Spectral peaks", peaks_text), row("Strongest correlations", correlations_text),
                row("Trend (m/s² per s)", [](const ResidualAnalysis& r) {
                  return signed_num(r.trend_per_s) + " ± " + num(r.trend_std_error, 2) +
                         (r.trend_significant ? " <b>significant</b>" : "");
                })});
  }
}

void candidates_table(const std::vector<CandidateTrial>& candidates, const std::string& chosen, Page& page) {
  std::vector<std::vector<std::string>> rows;
  std::vector<std::string> classes;
  for (const auto& c : candidates) {
    const bool tried = c.skipped.empty();
    const bool is_chosen = tried && !chosen.empty() && c.effect == chosen;
    rows.push_back({escape(with_needed(c.effect, c.with)), tried ? num(c.rmse_train) : "",
                    tried ? num(c.rmse_validation) : "", tried ? num(c.statistic) : "", tried ? p_value(c.p_value) : "",
                    tried ? (c.significant ? "yes" : "no") : "",
                    is_chosen ? "chosen" : escape(tried ? c.rejected_by : "not tried: " + c.skipped)});
    classes.emplace_back(is_chosen ? "chosen" : "");
  }
  if (rows.empty()) {
    page.paragraph("No candidates.", "note");
    return;
  }
  page.table({"Effect", "RMSE train", "RMSE validation", "Statistic", "p", "Significant", "Note"}, rows, classes,
             "nowrap");
}

void candidates_section(const Diagnosis& d, Page& page) {
  page.heading(2, "Candidates tried");
  for (std::size_t i = 0; i < d.steps.size(); ++i) {
    page.heading(3, "Step " + std::to_string(i + 1) + ": " + d.steps[i].effect + " chosen");
    candidates_table(d.steps[i].candidates, d.steps[i].effect, page);
  }
  page.heading(3, "Step " + std::to_string(d.steps.size() + 1) + ": the search stopped");
  const bool any_significant = std::any_of(d.last_candidates.begin(), d.last_candidates.end(),
                                           [](const CandidateTrial& c) { return c.significant; });
  if (d.last_candidates.empty()) {
    page.paragraph("No further candidate was tried.");
  } else if (!any_significant) {
    page.paragraph("No candidate passed the significance rule (" + d.significance_rule + ").");
  } else {  // e.g. the step limit, or the rule's minimum improvement beside the test
    page.paragraph("The search stopped here under its rule (" + d.significance_rule + ").");
  }
  candidates_table(d.last_candidates, "", page);
}

void plots_section(const std::vector<Plot>& plots, const GnuplotResult& rendered, Page& page) {
  page.heading(2, "Plots");
  if (!rendered.error.empty()) {
    page.paragraph("Plots need gnuplot (Debian package gnuplot-nox): " + rendered.error + ".", "note");
    return;
  }
  if (plots.empty()) page.paragraph("The diagnosis holds no series, spectra or convergence to plot.", "note");
  std::string group;
  for (std::size_t i = 0; i < plots.size() && i < rendered.svgs.size(); ++i) {
    if (plots[i].group != group) {
      group = plots[i].group;
      page.heading(3, group);
    }
    page.add("<figure>\n<div class=\"figtitle\">" + escape(plots[i].title) + "</div>\n" + rendered.svgs[i] +
             "\n<figcaption>" + escape(plots[i].caption) + "</figcaption>\n</figure>\n");
  }
}

void write_text(const std::filesystem::path& file, const std::string& text) {
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  out << text;
  if (!out.flush()) throw std::invalid_argument("cannot write " + file.string());
}

}  // namespace

std::string summary_line(const Diagnosis& d) {
  char text[400];
  std::string line;
  if (d.base.velocity && d.final.velocity) {
    std::snprintf(text, sizeof text,
                  "velocity RMSE on the validation window %.3f -> %.3f m/s (horizontal; x %.3f -> %.3f, y %.3f -> %.3f",
                  d.base.velocity->validation.horizontal, d.final.velocity->validation.horizontal,
                  d.base.velocity->validation.axis.x(), d.final.velocity->validation.axis.x(),
                  d.base.velocity->validation.axis.y(), d.final.velocity->validation.axis.y());
    line = text;
    if (d.zero_velocity) {
      std::snprintf(text, sizeof text, "; zero velocity %.3f", d.zero_velocity->validation.horizontal);
      line += text;
    }
    line += ")";
    if (!d.base.velocity->note.empty()) line += " [base: " + d.base.velocity->note + "]";
    if (!d.final.velocity->note.empty()) line += " [final: " + d.final.velocity->note + "]";
    line += "; ";
  } else {
    line = "no reference velocity, so no velocity error; ";
  }
  std::snprintf(text, sizeof text, "specific-force residual %.4f -> %.4f m/s^2; ", d.base.rmse_validation,
                d.final.rmse_validation);
  line += text;
  if (d.steps.empty()) {
    line += "no effect added";
  } else {
    std::vector<std::string> effects;
    for (const auto& step : d.steps) effects.push_back(with_needed(step.effect, step.with));
    line += std::to_string(d.steps.size()) + (d.steps.size() == 1 ? " effect added (" : " effects added (") +
            join(effects, ", ") + ")";
  }
  return line;
}

nlohmann::json report_json(const Diagnosis& d) {
  json steps = json::array();
  for (const auto& step : d.steps) steps.push_back(step_json(d, step));
  json unexplained = json::array();
  for (const auto& u : d.unexplained) unexplained.push_back(unexplained_json(u));
  json series = json::array();
  for (const auto& s : d.series) {
    series.push_back({{"axis", s.axis},
                      {"samples", s.t.size()},
                      {"t_start", s.t.empty() ? json(nullptr) : number(s.t.front())},
                      {"t_end", s.t.empty() ? json(nullptr) : number(s.t.back())}});
  }
  return {{"session", d.session},
          {"summary", summary_line(d)},
          {"warnings", d.warnings},
          {"imu_axes", d.imu_axes},
          {"zero_velocity_rmse_m_s", velocity_json(d.zero_velocity)},
          {"model", d.model},
          {"axes", d.axes},
          {"velocity_source", d.velocity_source},
          {"train_window", {{"start", number(d.train_start)}, {"end", number(d.train_end)}}},
          {"validation_window", {{"start", number(d.validate_start)}, {"end", number(d.validate_end)}}},
          {"significance_rule", d.significance_rule},
          {"base", fit_json(d, d.base, d.base_residual)},
          {"steps", std::move(steps)},
          {"last_candidates", candidates_json(d.last_candidates)},
          {"final", fit_json(d, d.final, d.final_residual)},
          {"residual_white", d.residual_white},
          {"unexplained", std::move(unexplained)},
          {"series", std::move(series)}};
}

void write_report_json(const Diagnosis& diagnosis, const std::filesystem::path& file) {
  write_text(file, report_json(diagnosis).dump(2) + "\n");
}

void write_report_html(const Diagnosis& d, const std::filesystem::path& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw std::invalid_argument("cannot create report directory " + dir.string() + ": " + ec.message());

  std::map<std::string, std::string> data;
  const std::vector<Plot> plots = make_plots(d, data);
  std::vector<GnuplotFigure> figures;
  for (const auto& plot : plots) figures.push_back(plot.figure);
  const GnuplotResult rendered = render_svg_figures(figures, data);
  if (!rendered.error.empty())
    spdlog::warn("report: no plots in {}: {}", (dir / "report.html").string(), rendered.error);

  Page page;
  page.add("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>imubridge diagnose: " +
           escape(d.session) + "</title>\n<style>" + std::string(kStyle) + "</style>\n</head>\n<body>\n");
  page.heading(1, "imubridge diagnose");
  page.paragraph(d.session + " · " + d.model + " model · axes " + join(d.axes, ", "), "note");
  banner(d, page);
  summary_section(d, page);
  search_section(d, page);
  unexplained_section(d, page);
  plots_section(plots, rendered, page);
  parameters_section(d, page);
  residual_section(d, page);
  candidates_section(d, page);
  page.add("</body>\n</html>\n");
  write_text(dir / "report.html", page.html());
}

std::string with_needed(const std::string& effect, const std::vector<std::string>& with) {
  std::string out = effect;
  for (std::size_t i = 0; i < with.size(); ++i) out += (i == 0 ? " (with " : ", ") + with[i];
  return with.empty() ? out : out + ")";
}

}  // namespace imubridge::diagnose
