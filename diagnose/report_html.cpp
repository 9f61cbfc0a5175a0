// report.html: one self-contained page for people, its plots inlined as SVG.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "diagnose/report.hpp"
#include "diagnose/report_parts.hpp"

namespace imubridge::diagnose {
namespace {

using report_parts::analysis_for;
using report_parts::axis_name;
using report_parts::join;
using report_parts::Plot;

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
  if (kind == "velocity ramp") return "velocity that ramps";
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
    const std::string effect = with_needed(c.effect, c.with) + (c.held.empty() ? "" : " (with " + c.held + ")");
    rows.push_back({escape(effect), tried ? num(c.rmse_train) : "", tried ? num(c.rmse_validation) : "",
                    tried ? num(c.statistic) : "", tried ? p_value(c.p_value) : "",
                    tried ? (c.significant ? "yes" : "no") : "",
                    is_chosen ? (c.admitted_by.empty() ? "chosen" : "chosen by " + escape(c.admitted_by))
                              : escape(tried ? c.rejected_by : "not tried: " + c.skipped)});
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

}  // namespace

void write_report_html(const Diagnosis& d, const std::filesystem::path& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw std::invalid_argument("cannot create report directory " + dir.string() + ": " + ec.message());

  std::map<std::string, std::string> data;
  const std::vector<Plot> plots = report_parts::make_plots(d, data);
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
  report_parts::write_text(dir / "report.html", page.html());
}

}  // namespace imubridge::diagnose
