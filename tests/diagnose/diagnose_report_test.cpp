// report.json and report.html from a Diagnosis built by hand: its documented fields and values, null for what could not
// be computed, small and deterministic output, escaping, the tables and banner, and the gnuplot figures.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <numbers>
#include <optional>
#include <regex>
#include <set>
#include <string>

#include "diagnose/gnuplot.hpp"
#include "diagnose/report.hpp"
#include "tests/support/run_command.hpp"

namespace imubridge::diagnose {
namespace {

using test::slurp;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

ResidualAnalysis analysis(double rms, bool white, double line_hz) {
  ResidualAnalysis r;
  r.samples = 4000;
  r.rms = rms;
  r.mean = 0.001;
  r.autocorrelation.assign(50, 0.1);
  r.ljung_box_lags = 20;
  r.ljung_box_q = white ? 18.0 : 240.0;
  r.ljung_box_p = white ? 0.58 : 1e-12;
  r.white = white;
  for (int i = 0; i <= 256; ++i) {  // 0..100 Hz; a line at line_hz when > 0
    const double f = 100.0 * i / 256.0;
    r.frequency_hz.push_back(f);
    r.psd.push_back(1e-4 * (1.0 + (line_hz > 0 && std::abs(f - line_hz) < 0.3 ? 400.0 : 0.0)));
  }
  for (int i = 0; i < 8; ++i) r.peaks.push_back({line_hz + i, 40.0 - i, i == 7});
  for (int i = 0; i < 7; ++i) r.correlations.push_back({"gyro.y", 0.01 * i, 0.3 - 0.01 * i, 0.05, i < 2});
  r.trend_per_s = 1e-4;
  r.trend_std_error = 2e-4;
  return r;
}

ModelFit fit(std::vector<std::string> effects, double rmse_train, double rmse_validation) {
  ModelFit f;
  f.base_params = {{"r", 0.12, 0.003, "m"}, {"mu", 0.4, kNaN, "1/m"}};
  for (const auto& effect : effects) f.effect_params.push_back({{effect + ".k", 0.5, 0.01, "1/s"}});
  f.effects = std::move(effects);
  f.free_parameters = 2 + f.effects.size();
  f.rmse_train = rmse_train;
  f.rmse_validation = rmse_validation;
  f.convergence = {3.0, 1.5, 1.2 * rmse_train + 1.0, rmse_train + 1.0};
  return f;
}

CandidateTrial candidate(std::string effect, double rmse_validation, bool significant, std::string skipped = {}) {
  return {.effect = std::move(effect),
          .rmse_train = rmse_validation * 0.95,
          .rmse_validation = rmse_validation,
          .statistic = 12.0,
          .p_value = significant ? 1e-6 : 0.4,
          .significant = significant,
          .rejected_by = significant ? "" : "F-test: p = 0.4, not below 0.001 (0.01 / 10 candidates)",
          .skipped = std::move(skipped)};
}

// Two steps (linear_drag, then accel_bias) and a 37.5 Hz line left unexplained on axis x.
Diagnosis sample_diagnosis() {
  Diagnosis d;
  d.session = "flight.db#3";
  d.model = "paper";
  d.axes = {"x"};
  d.velocity_source = "imu";
  d.train_start = 0.0;
  d.train_end = 33.0;
  d.validate_start = 33.0;
  d.validate_end = 53.0;
  d.significance_rule = "F-test on validation RSS, p < 0.01, and at least 2 % lower validation RMSE";
  d.base = fit({}, 0.9, 1.0);
  d.base_residual = {analysis(1.0, false, 37.5)};
  Step drag;
  drag.effect = "linear_drag";
  drag.fit = fit({"linear_drag"}, 0.5, 0.6);
  drag.params = drag.fit.effect_params[0];
  drag.rmse_train_before = 0.9;
  drag.rmse_validation_before = 1.0;
  drag.candidates = {candidate("linear_drag", 0.6, true), candidate("wind", 0.8, true),
                     candidate("gyro_bias", 0.0, false, "needs a reference velocity")};
  drag.residual = {analysis(0.6, false, 37.5)};
  Step bias;
  bias.effect = "accel_bias";
  bias.fit = fit({"linear_drag", "accel_bias"}, 0.4, 0.45);
  bias.params = bias.fit.effect_params[1];
  bias.params[0].std_error = kNaN;
  bias.rmse_train_before = 0.5;
  bias.rmse_validation_before = 0.6;
  bias.candidates = {candidate("accel_bias", 0.45, true), candidate("wind", 0.58, true)};
  bias.residual = {analysis(0.45, false, 37.5)};
  d.steps = {drag, bias};
  d.last_candidates = {candidate("wind", 0.449, false), candidate("vibration", 0.447, false)};
  d.final = bias.fit;
  d.final_residual = {analysis(0.45, false, 37.5)};
  d.residual_white = false;
  d.unexplained = {{"frequency", "x", "line at 37.5 Hz, 40x the median power", 37.5, "", 0.0, 40.0}};
  AxisSeries s;
  s.axis = "x";
  for (int i = 0; i < 4000; ++i) {  // 20 s at 200 Hz: longer than the fit figure's excerpt
    const double t = 33.0 + i / 200.0;
    const double motion = std::sin(2 * std::numbers::pi * 0.3 * t) * (t >= 40.0 && t < 50.0 ? 3.0 : 1.0);
    s.t.push_back(t);
    s.final_model.push_back(motion);
    s.base_model.push_back(0.7 * motion);
    s.measured.push_back(motion + 0.1 * std::sin(2 * std::numbers::pi * 37.5 * t));
  }
  d.series = {s};
  return d;
}

std::filesystem::path fresh_dir(const std::string& name) {
  const auto dir =
      std::filesystem::temp_directory_path() / ("imubridge_report_test_" + std::to_string(::getpid()) + "_" + name);
  std::filesystem::remove_all(dir);
  return dir;
}

std::size_t count(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (auto at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

// Runs `body` with PATH set to `path`, then restores it.
template <typename Body>
void with_path(const std::string& path, Body body) {
  const char* old = std::getenv("PATH");
  const std::optional<std::string> saved = old ? std::optional<std::string>(old) : std::nullopt;
  ::setenv("PATH", path.c_str(), 1);
  body();
  if (saved)
    ::setenv("PATH", saved->c_str(), 1);
  else
    ::unsetenv("PATH");
}

TEST(DiagnoseReportJson, HasTheIssueFieldsWithTheirValues) {
  const auto j = report_json(sample_diagnosis());
  EXPECT_EQ(j["session"], "flight.db#3");
  EXPECT_EQ(j["model"], "paper");
  EXPECT_EQ(j["axes"], nlohmann::json::array({"x"}));
  EXPECT_EQ(j["velocity_source"], "imu");
  EXPECT_DOUBLE_EQ(j["train_window"]["end"].get<double>(), 33.0);
  EXPECT_DOUBLE_EQ(j["validation_window"]["end"].get<double>(), 53.0);
  EXPECT_EQ(j["significance_rule"].get<std::string>().substr(0, 6), "F-test");

  EXPECT_DOUBLE_EQ(j["base"]["rmse_train"].get<double>(), 0.9);
  EXPECT_DOUBLE_EQ(j["base"]["rmse_validation"].get<double>(), 1.0);
  ASSERT_EQ(j["base"]["params"].size(), 2u);
  EXPECT_EQ(j["base"]["params"][0]["name"], "r");
  EXPECT_EQ(j["base"]["params"][0]["component"], "base");
  EXPECT_EQ(j["base"]["residual_white"], false);
  EXPECT_EQ(j["base"]["residual"][0]["axis"], "x");

  ASSERT_EQ(j["steps"].size(), 2u);
  const auto& first = j["steps"][0];
  EXPECT_EQ(first["effect"], "linear_drag");
  EXPECT_EQ(j["steps"][1]["effect"], "accel_bias");
  ASSERT_EQ(first["params"].size(), 1u);
  EXPECT_EQ(first["params"][0]["name"], "linear_drag.k");
  EXPECT_DOUBLE_EQ(first["params"][0]["value"].get<double>(), 0.5);
  EXPECT_DOUBLE_EQ(first["params"][0]["std_error"].get<double>(), 0.01);
  EXPECT_EQ(first["params"][0]["unit"], "1/s");
  EXPECT_DOUBLE_EQ(first["rmse_train"].get<double>(), 0.5);
  EXPECT_DOUBLE_EQ(first["rmse_validation"].get<double>(), 0.6);
  EXPECT_DOUBLE_EQ(first["rmse_validation_before"].get<double>(), 1.0);
  EXPECT_EQ(first["residual_white"], false);
  ASSERT_EQ(first["candidates"].size(), 3u);
  EXPECT_EQ(first["candidates"][2]["skipped"], "needs a reference velocity");
  EXPECT_EQ(first["model"]["effects"], nlohmann::json::array({"linear_drag"}));

  EXPECT_EQ(j["final"]["effects"], nlohmann::json::array({"linear_drag", "accel_bias"}));
  EXPECT_DOUBLE_EQ(j["final"]["rmse_validation"].get<double>(), 0.45);
  EXPECT_EQ(j["final"]["params"].size(), 4u);
  EXPECT_EQ(j["final"]["params"][3]["component"], "accel_bias");
  EXPECT_EQ(j["last_candidates"].size(), 2u);

  EXPECT_EQ(j["residual_white"], false);
  ASSERT_EQ(j["unexplained"].size(), 1u);
  EXPECT_EQ(j["unexplained"][0]["kind"], "frequency");
  EXPECT_EQ(j["unexplained"][0]["axis"], "x");
  EXPECT_DOUBLE_EQ(j["unexplained"][0]["frequency_hz"].get<double>(), 37.5);
  EXPECT_EQ(j["unexplained"][0]["where"], "line at 37.5 Hz, 40x the median power");
  EXPECT_FALSE(j["unexplained"][0].contains("signal"));  // only a correlation names a signal
  EXPECT_EQ(j["series"][0]["samples"], 4000);
}

TEST(DiagnoseReportJson, NanBecomesNull) {
  const auto j = report_json(sample_diagnosis());
  EXPECT_TRUE(j["base"]["params"][1]["std_error"].is_null());
  EXPECT_TRUE(j["steps"][1]["params"][0]["std_error"].is_null());
  EXPECT_DOUBLE_EQ(j["base"]["params"][0]["std_error"].get<double>(), 0.003);
}

TEST(DiagnoseReportJson, KeepsSummariesNotArrays) {
  const auto d = sample_diagnosis();
  const auto j = report_json(d);
  const auto& residual = j["final"]["residual"][0];
  EXPECT_EQ(residual["peaks"].size(), kReportTopEntries);
  EXPECT_EQ(residual["peaks_found"], 8);
  EXPECT_EQ(residual["correlations"].size(), kReportTopEntries);
  EXPECT_EQ(residual["significant_correlations"], 2);
  EXPECT_DOUBLE_EQ(residual["ljung_box"]["p"].get<double>(), 1e-12);
  EXPECT_EQ(residual["ljung_box"]["white"], false);
  EXPECT_FALSE(residual.contains("psd"));
  EXPECT_FALSE(j["series"][0].contains("measured"));
  // 4000-sample series and 257-bin spectra in five analyses would be far above this.
  EXPECT_LT(j.dump(2).size(), 40000u);
}

TEST(DiagnoseReportJson, SameDiagnosisSameBytes) {
  const auto dir = fresh_dir("json");
  std::filesystem::create_directories(dir);
  write_report_json(sample_diagnosis(), dir / "a.json");
  write_report_json(sample_diagnosis(), dir / "b.json");
  const std::string a = slurp(dir / "a.json");
  EXPECT_FALSE(a.empty());
  EXPECT_EQ(a, slurp(dir / "b.json"));
  EXPECT_EQ(nlohmann::json::parse(a), report_json(sample_diagnosis()));
  std::filesystem::remove_all(dir);
}

TEST(DiagnoseReportJson, UnwritableFileThrows) {
  // A failure while writing, not a mistake in what was asked: exit 1 (docs/operations.md, "Exit codes and files").
  EXPECT_THROW(write_report_json(sample_diagnosis(), "/nonexistent-dir/report.json"), std::runtime_error);
}

TEST(DiagnoseReportHtml, HasTablesAndTheNotWhiteBanner) {
  const auto dir = fresh_dir("tables");
  write_report_html(sample_diagnosis(), dir);
  const std::string html = slurp(dir / "report.html");
  EXPECT_EQ(html.rfind("<!DOCTYPE html>", 0), 0u);
  EXPECT_NE(html.find("class=\"banner bad\""), std::string::npos);
  EXPECT_NE(html.find("The residual is not white"), std::string::npos);
  EXPECT_NE(html.find("<li>axis x, periodic component: line at 37.5 Hz, 40x the median power</li>"), std::string::npos);
  for (const char* heading : {"Summary", "Model search", "Unexplained structure", "Final model parameters",
                              "Residual analysis (validation window)", "Candidates tried"}) {
    EXPECT_NE(html.find(std::string(heading) + "</h2>"), std::string::npos) << heading;
  }
  EXPECT_NE(html.find("<td>+ linear_drag</td>"), std::string::npos);
  EXPECT_NE(html.find("<td>+ accel_bias</td>"), std::string::npos);
  EXPECT_NE(html.find("accel_bias.k = 0.5 ± n/a 1/s"), std::string::npos);  // NaN standard error
  EXPECT_NE(html.find("not tried: needs a reference velocity"), std::string::npos);
  EXPECT_EQ(count(html, "<tr class=\"chosen\">"), 2u);               // one chosen candidate per step
  EXPECT_EQ(html.find("http://"), html.find("http://www.w3.org/"));  // nothing to fetch: only SVG namespaces
  EXPECT_EQ(html.find("<script"), std::string::npos);
  std::filesystem::remove_all(dir);
}

TEST(DiagnoseReportHtml, WhiteResidualHasNoRedBanner) {
  auto d = sample_diagnosis();
  d.residual_white = true;
  d.unexplained.clear();
  const auto dir = fresh_dir("white");
  write_report_html(d, dir);
  const std::string html = slurp(dir / "report.html");
  EXPECT_EQ(html.find("banner bad"), std::string::npos);
  EXPECT_NE(html.find("class=\"banner good\""), std::string::npos);
  std::filesystem::remove_all(dir);
}

TEST(DiagnoseReportHtml, EscapesWhatComesFromTheData) {
  auto d = sample_diagnosis();
  d.session = "<script>alert('x')</script> & co";
  d.unexplained[0].where = "line <b>at</b> 37.5 Hz & \"more\"";
  const auto dir = fresh_dir("escape");
  write_report_html(d, dir);
  const std::string html = slurp(dir / "report.html");
  EXPECT_EQ(html.find("<script>"), std::string::npos);
  EXPECT_EQ(html.find("<b>at</b>"), std::string::npos);
  EXPECT_NE(html.find("&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt; &amp; co"), std::string::npos);
  EXPECT_NE(html.find("line &lt;b&gt;at&lt;/b&gt; 37.5 Hz &amp; &quot;more&quot;"), std::string::npos);
  std::filesystem::remove_all(dir);
}

TEST(DiagnoseReportHtml, InlinesGnuplotFigures) {
  if (!find_on_path("gnuplot")) GTEST_SKIP() << "gnuplot is not installed (Debian package gnuplot-nox)";
  const auto dir = fresh_dir("svg");
  write_report_html(sample_diagnosis(), dir);
  const std::string html = slurp(dir / "report.html");
  // Axis x: measured vs model, residual, spectrum; then the convergence of the three fits.
  EXPECT_EQ(count(html, "<svg"), 4u);
  EXPECT_EQ(count(html, "</svg>"), 4u);
  EXPECT_EQ(html.find("<?xml"), std::string::npos);
  EXPECT_EQ(html.find("Plots need gnuplot"), std::string::npos);
  // The excerpt is the 10 s with the most motion: 40-50 s in the sample flight.
  std::smatch excerpt;
  ASSERT_TRUE(std::regex_search(html, excerpt, std::regex("measured vs model, validation ([0-9.]+)–([0-9.]+) s")));
  EXPECT_NEAR(std::stod(excerpt[1]), 40.0, 0.5);
  EXPECT_NEAR(std::stod(excerpt[2]) - std::stod(excerpt[1]), 10.0, 0.1);
  EXPECT_NE(html.find("37.5 Hz</text>"), std::string::npos) << "the unexplained line is labelled on the spectrum";
  EXPECT_NE(html.find("+ accel_bias</text>"), std::string::npos) << "each fit's convergence is in the legend";
  // One page, many figures: no id may repeat.
  const std::regex id_attribute(R"re(\sid=['"]([^'"]+)['"])re");
  std::set<std::string> ids;
  std::size_t total = 0;
  for (auto it = std::sregex_iterator(html.begin(), html.end(), id_attribute); it != std::sregex_iterator(); ++it) {
    ids.insert((*it)[1]);
    ++total;
  }
  EXPECT_GT(total, 4u);
  EXPECT_EQ(ids.size(), total);
  // Same Diagnosis, same page.
  const auto again = fresh_dir("svg_again");
  write_report_html(sample_diagnosis(), again);
  EXPECT_EQ(html, slurp(again / "report.html"));
  std::filesystem::remove_all(dir);
  std::filesystem::remove_all(again);
}

TEST(DiagnoseReportHtml, WithoutGnuplotStillWritesTheTables) {
  const auto dir = fresh_dir("nognuplot");
  const auto empty_bin = fresh_dir("empty_bin");
  std::filesystem::create_directories(empty_bin);
  with_path(empty_bin.string(), [&] { write_report_html(sample_diagnosis(), dir); });
  const std::string html = slurp(dir / "report.html");
  EXPECT_EQ(html.find("<svg"), std::string::npos);
  EXPECT_NE(html.find("Plots need gnuplot (Debian package gnuplot-nox)"), std::string::npos);
  EXPECT_NE(html.find("Model search</h2>"), std::string::npos);
  std::filesystem::remove_all(dir);
  std::filesystem::remove_all(empty_bin);
}

TEST(DiagnoseReportHtml, EmptyDiagnosisStillGivesAPage) {
  Diagnosis d;
  d.axes = {"x", "y"};
  d.base.convergence = {2.0, 0.0};  // a cost of zero: no log scale, and still a figure
  const auto dir = fresh_dir("empty");
  write_report_html(d, dir);
  const std::string html = slurp(dir / "report.html");
  EXPECT_NE(html.find("Model search</h2>"), std::string::npos);
  EXPECT_NE(html.find("No further candidate was tried."), std::string::npos);
  if (find_on_path("gnuplot")) {
    EXPECT_EQ(count(html, "<svg"), 1u);
    EXPECT_EQ(html.find("Plots need gnuplot"), std::string::npos);
  }
  const auto j = report_json(d);
  EXPECT_TRUE(j["base"]["residual_white"].is_null());  // nothing analysed: no verdict
  EXPECT_EQ(j["steps"].size(), 0u);
  std::filesystem::remove_all(dir);
}

TEST(DiagnoseReportGnuplot, InlineSvgPrefixesIdsAndReferences) {
  const std::string svg =
      "<?xml version=\"1.0\"?>\n<svg width=\"10\">\n<g id=\"gnuplot_canvas\"><path id='gpPt0'/>"
      "<use xlink:href='#gpPt0'/><g filter=\"url(#textbox)\"/></g></svg>\n";
  EXPECT_EQ(inline_svg(svg, "f1_"),
            "<svg width=\"10\">\n<g id=\"f1_gnuplot_canvas\"><path id='f1_gpPt0'/><use xlink:href='#f1_gpPt0'/>"
            "<g filter=\"url(#f1_textbox)\"/></g></svg>");
  EXPECT_EQ(gnuplot_quote("it's a\nname"), "'it''s aname'");
}

}  // namespace
}  // namespace imubridge::diagnose
