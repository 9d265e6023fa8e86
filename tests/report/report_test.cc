// report/: section builders (what they keep, what they tolerate) and the page's data embedding.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "report/report.h"

namespace vb::report {
namespace {

Json Load(const std::string& name) {
  std::ifstream in(std::string(VB_SOURCE_DIR) + "/tests/report/" + name);
  return Json::parse(in);
}

const Json* Find(const Json& sections, const std::string& kind, const std::string& title_part = "") {
  for (const auto& s : sections)
    if (s["kind"] == kind && (title_part.empty() || s.value("title", std::string()).find(title_part) != std::string::npos))
      return &s;
  return nullptr;
}

TEST(ReportDiagnosis, RendersEveryFieldOfAFullDiagnosis) {
  const Json s = DiagnosisSections(Load("diagnosis_fixture.json"));
  const Json* summary = Find(s, "table", "Gap diagnosis");
  ASSERT_NE(summary, nullptr);
  const std::string text = summary->dump();
  for (const char* k : {"noise_floor_A", "gap.holdout_rmse_A", "verdict"}) EXPECT_NE(text.find(k), std::string::npos) << k;
  EXPECT_NE(text.find("taghizadeh2009"), std::string::npos);
  const Json* shares = Find(s, "bars", "Where the gap lies");
  ASSERT_NE(shares, nullptr);
  EXPECT_EQ((*shares)["labels"].size(), 3u);
  EXPECT_DOUBLE_EQ((*shares)["values"][0].get<double>(), 0.62);
  const Json* ranking = Find(s, "table", "Candidate effects");
  ASSERT_NE(ranking, nullptr);
  EXPECT_EQ((*ranking)["rows"].size(), 2u);
  EXPECT_EQ((*ranking)["rows"][0][0], "coil_heating");
  const Json* overlay = Find(s, "lines", "p07-r1");
  ASSERT_NE(overlay, nullptr);
  ASSERT_EQ((*overlay)["series"].size(), 3u);
  EXPECT_EQ((*overlay)["series"][0]["name"], "measured");
  EXPECT_EQ((*overlay)["series"][2]["name"], "fitted");
  EXPECT_EQ(Find(s, "note", ""), nullptr);  // nothing missing
}

TEST(ReportDiagnosis, ToleratesMissingAndMalformedParts) {
  const Json s = DiagnosisSections(Load("diagnosis_partial.json"));
  const Json* note = Find(s, "note");
  ASSERT_NE(note, nullptr);
  const std::string text = (*note)["text"];
  for (const char* k : {"noise_floor_A", "gap", "ranking", "overlays"}) EXPECT_NE(text.find(k), std::string::npos) << k;
  EXPECT_EQ(text.find("where"), std::string::npos);  // present (partly usable)
  const Json* where = Find(s, "table", "Per phase");
  ASSERT_NE(where, nullptr);
  EXPECT_EQ((*where)["rows"].size(), 2u);  // the non-object entry is skipped
  EXPECT_FALSE(DiagnosisSections(Json::array()).empty());
  EXPECT_FALSE(DiagnosisSections(Json::object()).empty());
}

TEST(ReportTraces, DecimationBoundsPointsAndKeepsPeaks) {
  TraceData t;
  t.label = "run 1";
  t.sample_period_s = 1e-5;
  const std::size_t n = 100000;
  std::vector<double> i(n), gate(n);
  for (std::size_t k = 0; k < n; ++k) {
    i[k] = std::sin(k * 1e-3);
    gate[k] = (k / 37) % 2;
  }
  i[54321] = 5.0;  // a one-sample spike must survive
  t.channels = {{"i_A", i}, {"gate", gate}};
  const Json s = TraceSection({t}, 2000);
  const Json& run = s["runs"][0];
  EXPECT_LE(run["t"].size(), 2100u);
  EXPECT_GT(run["t"].size(), 500u);
  double peak = -1, t_peak = 0;
  for (std::size_t k = 0; k < run["i_A"].size(); ++k)
    if (run["i_A"][k].get<double>() > peak) {
      peak = run["i_A"][k].get<double>();
      t_peak = run["t"][k].get<double>();
    }
  EXPECT_EQ(peak, 5.0);
  // At its bucket's first or last sample (1000 buckets of 100 samples): a bucket is narrower than a pixel.
  EXPECT_NEAR(t_peak, 54321 * 1e-5, 100 * 1e-5);
  // The gate's edges: both levels in every bucket that holds an edge, so the band is drawn full.
  double gate_lo = 1, gate_hi = 0;
  for (const auto& g : run["gate"]) {
    gate_lo = std::min(gate_lo, g.get<double>());
    gate_hi = std::max(gate_hi, g.get<double>());
  }
  EXPECT_EQ(gate_lo, 0.0);
  EXPECT_EQ(gate_hi, 1.0);
  EXPECT_EQ(run["samples"], n);
  // Short traces are kept whole.
  t.channels = {{"i_A", {1, 2, 3}}};
  EXPECT_EQ(TraceSection({t})["runs"][0]["t"].size(), 3u);
}

TEST(ReportMaps, StaticMapIsPositionAgainstDutyOneCurvePerPressureAndOnePlotPerVariant) {
  auto key = [](const char* name, const char* field, double v, double duty, int repeat) {
    return RunKey{name, {{field, v}, {"controller.open_loop_pwm.segments[0].duty", duty}}, repeat};
  };
  const char* p = "conditions.supply_pressure_Pa";
  const char* f = "controller.open_loop_pwm.segments[0].frequency_Hz";
  std::vector<MapPoint> pts = {{key("m/fig8", p, 0, 0.2, -1), 10},     {key("m/fig8", p, 0, 0.6, -1), 60},
                               {key("m/fig8", p, 4e5, 0.2, -1), 5},    {key("m/fig8", p, 4e5, 0.6, 1), 50},
                               {key("m/fig8", p, 4e5, 0.6, 0), 52},    {key("m/fig9", f, 25, 0.2, -1), 20},
                               {key("m/fig9", f, 25, 0.6, -1), 70},    {key("m/fig9", f, 100, 0.6, -1), 40}};
  const Json s = StaticMapSection(pts, "pct");
  ASSERT_EQ(s.size(), 2u) << "fig8 and fig9, each its own plot";
  const Json& fig8 = s[0];
  EXPECT_EQ(fig8["x_label"], "duty [%]");
  ASSERT_EQ(fig8["series"].size(), 2u);
  EXPECT_EQ(fig8["series"][0]["name"], "0 bar");
  EXPECT_EQ(fig8["series"][1]["name"], "4 bar");
  EXPECT_DOUBLE_EQ(fig8["series"][1]["x"][1].get<double>(), 60.0);  // duty in %
  EXPECT_DOUBLE_EQ(fig8["series"][1]["y"][1].get<double>(), 51.0);  // repeats averaged
  EXPECT_NE(s[1]["title"].get<std::string>().find("m/fig9"), std::string::npos);
  EXPECT_EQ(s[1]["series"][1]["name"], "100 Hz");
  EXPECT_TRUE(StaticMapSection({{NamedRun("a"), 1}, {NamedRun("b"), 2}, {NamedRun("c"), 3}}, "pct").empty());
}

TEST(ReportBatch, OverlaysTheComparedLawsWithTheErrorOverTheMetricWindow) {
  std::vector<RunInfo> runs;
  for (const char* law : {"pi_current", "fuzzy_current"}) {
    RunInfo r;
    r.id = static_cast<std::int64_t>(runs.size()) + 1;
    r.key = NamedRun(std::string("cmp/") + law);
    r.controller = law;
    r.status = RunStatus::kDone;
    r.metrics = {{"rmse", 1e-3 * r.id}, {"driver_loss_W", 0.25}};
    r.spec_json = R"({"duration_s": 0.1, "metric_window": {"start_s": 0.02, "end_s": 0.1}, "conditions": {"supply_V": 24}})";
    r.started_unix_s = 1.7e9;
    r.finished_unix_s = 1.7e9 + 1;
    r.trace.sample_period_s = 1e-4;
    std::vector<double> i(1001), ref(1001, 0.5);
    for (std::size_t k = 0; k < i.size(); ++k) i[k] = 0.5 + 0.002 * r.id * std::sin(k * 0.3);
    r.trace.channels = {{"i_A", i}, {"ref", ref}};
    runs.push_back(r);
  }
  const Json o = OverlaySection(runs);
  ASSERT_FALSE(o.is_null());
  EXPECT_EQ(o["series"].size(), 2u);
  EXPECT_EQ(o["y_label"], "current [mA]");
  EXPECT_EQ(o["e_label"], "error current - reference [mA]");
  EXPECT_DOUBLE_EQ(o["window"][0].get<double>(), 0.02);
  // The error is over the window only: 0.02-0.1 s, at most 2 mA (run 1) and 4 mA (run 2).
  EXPECT_GE(o["series"][0]["et"][0].get<double>(), 0.02 - 1e-12);
  double emax = 0;
  for (const auto& e : o["series"][1]["e"]) emax = std::max(emax, std::abs(e.get<double>()));
  EXPECT_NEAR(emax, 4.0, 0.05);
  // The batch page: meta (conditions, times), comparison, scatter, overlay, every run's traces.
  const Json b = BatchSections("local store x.db", 7, runs);
  std::vector<std::string> kinds;
  for (const auto& s : b) kinds.push_back(s["kind"]);
  EXPECT_EQ(kinds, (std::vector<std::string>{"meta", "note", "table", "scatter", "overlay", "traces"}));
  EXPECT_NE(b[0].dump().find("supply_V = 24"), std::string::npos) << b[0].dump();
  EXPECT_NE(b[0].dump().find("metric window 0.02-0.1 s"), std::string::npos) << b[0].dump();
  EXPECT_NE(b[0].dump().find("UTC"), std::string::npos);
  EXPECT_EQ(b[2]["columns"][1], "case");
  EXPECT_NE(b[2].dump().find("RMSE [mA]"), std::string::npos) << b[2].dump();
  EXPECT_EQ(b[3]["x_label"], "driver loss [mW]");
  EXPECT_EQ(b[5]["runs"].size(), 2u);
  // Open-loop runs have no reference: no overlay.
  for (auto& r : runs) r.controller = "open_loop_pwm";
  EXPECT_TRUE(OverlaySection(runs).is_null());
}

TEST(ReportPage, DataCannotCloseTheScriptElement) {
  const Json sections = Json::array({{{"kind", "note"}, {"text", "</script><script>alert(1)</script>"}}});
  const std::string html = RenderHtml("t <b>", sections);
  EXPECT_EQ(html.find("</script><script>alert"), std::string::npos);
  EXPECT_NE(html.find("\\u003c/script>"), std::string::npos);
  EXPECT_NE(html.find("<title>t &lt;b&gt;</title>"), std::string::npos);
  EXPECT_EQ(html.find("http://"), html.find("http://www.w3.org/2000/svg"));  // no network references
  // The one https:// is the licence comment of the inlined dygraphs, not something to load.
  const size_t licence = html.find("https://github.com/danvk/dygraphs/blob/");
  EXPECT_EQ(html.find("https://"), licence);
  EXPECT_EQ(html.find("https://", licence + 1), std::string::npos);
  EXPECT_EQ(html.find(" src="), std::string::npos);
  EXPECT_EQ(html.find("sourceMappingURL"), std::string::npos);
}

// The time series use Debian's dygraphs, inlined whole (the library the web dashboard serves), so the page stays
// one self-contained file.
TEST(ReportPage, InlinesDebiansDygraphs) {
  const std::string html = RenderHtml("t", Json::array());
  std::ifstream in("/usr/share/javascript/dygraphs/dygraph.min.js", std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  std::string js = ss.str();
  js = js.substr(0, js.rfind("//# sourceMappingURL="));
  ASSERT_GT(js.size(), 100000u);
  EXPECT_NE(html.find("<script>" + js + "</script>"), std::string::npos);
  EXPECT_LT(html.find("<script>" + js), html.find("id=\"vb-data\""));  // loaded before the renderer runs
  EXPECT_NE(html.find(".dygraph-legend"), std::string::npos);          // and its stylesheet
}

// Issue 28: one chart library for the page and the reports. The report inlines the dashboard's own files
// (web/static/format.js, charts.js, charts.css) byte for byte, before its renderer, and the renderer hands its
// charts to them; the SI prefix table it gives them is the CLI's.
TEST(ReportPage, InlinesTheDashboardsChartAndFormatCode) {
  const std::string html = RenderHtml("t", Json::array());
  for (const char* f : {"format.js", "charts.js", "charts.css"}) {
    std::ifstream in(std::string(VB_SOURCE_DIR) + "/web/static/" + f, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    ASSERT_GT(ss.str().size(), 1000u) << f;
    const bool css = std::string(f).ends_with(".css");
    const size_t at = html.find((css ? "<style>" : "<script>") + ss.str() + (css ? "</style>" : "</script>"));
    EXPECT_NE(at, std::string::npos) << f << " is not inlined whole";
    EXPECT_LT(at, html.find("id=\"vb-data\"")) << f << " must load before the renderer";
  }
  // The renderer uses them: the shared palette and plot, the formatter given the CLI's prefixes.
  const size_t renderer = html.find("id=\"vb-data\"");
  for (const char* use : {"VBCharts.plot(", "VBCharts.heatmap(", "new VBCharts.Palette()", "VBCharts.PALETTE",
                          "VBFormat.use(data.units)", "palette.fixLaw(", "VBCharts.linkTime("})
    EXPECT_NE(html.find(use, renderer), std::string::npos) << use;
  EXPECT_NE(html.find("\"prefixes\":[{\"symbol\":"), std::string::npos) << "the SI prefix table in the data";
  EXPECT_NE(html.find("\"symbol\":\"m\",\"scale\":1000.0"), std::string::npos);
}

TEST(ReportRegression, TablesAndBarsFromAResult) {
  Json r = {{"suite", "ci"}, {"baseline", {{"name", "main"}, {"version", 2}}}, {"verdict", "regressed"},
            {"counts", {{"regressed", 1}, {"improved", 0}, {"unchanged", 1}, {"new", 0}}},
            {"findings", Json::array({{{"case", "hold/pi"}, {"metric", "rmse"}, {"verdict", "regressed"},
                                       {"direction", "lower"}, {"baseline", {{"mean", 0.0003}, {"spread", 0}, {"n", 3}}},
                                       {"now", {{"mean", 0.0011}, {"spread", 0}, {"n", 3}}}, {"delta", 0.0008},
                                       {"allowed", 0.0004}},
                                      {{"case", "hold/pi"}, {"metric", "switches"}, {"verdict", "unchanged"},
                                       {"direction", "lower"}, {"baseline", {{"mean", 800}, {"spread", 0}, {"n", 3}}},
                                       {"now", {{"mean", 800}, {"spread", 0}, {"n", 3}}}, {"delta", 0}, {"allowed", 40}}})}};
  const Json s = RegressionSections(r);
  ASSERT_GE(s.size(), 3u);
  EXPECT_EQ(s[0]["class"], "bad");
  const Json* table = Find(s, "table");
  ASSERT_NE(table, nullptr);
  EXPECT_EQ((*table)["row_classes"][0], "regressed");
  const Json* bars = Find(s, "bars");
  ASSERT_NE(bars, nullptr);
  EXPECT_DOUBLE_EQ((*bars)["values"][0].get<double>(), 2.0);  // twice the allowance
  EXPECT_DOUBLE_EQ((*bars)["values"][1].get<double>(), 0.0);
}

}  // namespace
}  // namespace vb::report
