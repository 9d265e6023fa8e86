// The HTML reports in a real browser: Debian's chromium, headless. Each page must finish rendering (its script
// writes "rendered-ok" into #vb-status only when every section drew without an exception), log nothing to the
// console, and a screenshot must show the plots. Skipped, saying so, when chromium is not installed
// (scripts/setup.sh installs it, so CI runs it).
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "../common/run_command.h"

namespace {

namespace fs = std::filesystem;
using vb::testing::RunCommand;

std::string Chromium() {
  for (const char* p : {"/usr/bin/chromium", "/usr/bin/chromium-browser"})
    if (::access(p, X_OK) == 0) return p;
  return "";
}

size_t Count(const std::string& s, const std::string& what) {
  size_t n = 0;
  for (size_t at = s.find(what); at != std::string::npos; at = s.find(what, at + 1)) ++n;
  return n;
}

class HeadlessReport : public ::testing::Test {
 protected:
  void SetUp() override {
    chromium_ = Chromium();
    if (chromium_.empty()) GTEST_SKIP() << "chromium is not installed (scripts/setup.sh installs it): not rendering";
    dir_ = ::testing::TempDir() + "/vb-headless-" + std::to_string(::getpid());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    if (!dir_.empty()) fs::remove_all(dir_);
  }
  std::string Browser(const std::string& args) {
    return "timeout 90 " + chromium_ + " --headless --no-sandbox --disable-gpu --hide-scrollbars --user-data-dir=" +
           dir_ + "/profile-" + std::to_string(++browsers_) + " --enable-logging=stderr --v=0 " + args;
  }
  // Loads the page; returns the DOM and browser log, failing the test on a missing marker or console output.
  std::string ExpectRenders(const std::string& html, const std::string& what) {
    auto r = RunCommand(Browser("--dump-dom file://" + html));
    EXPECT_EQ(r.exit_code, 0) << what << "\n" << r.out;
    // The status element's text, as the script left it (the script's own source also contains the words).
    EXPECT_NE(r.out.find("id=\"vb-status\">rendered-ok: "), std::string::npos)
        << what << ": the page did not finish rendering\n" << r.out.substr(0, 4000);
    EXPECT_EQ(r.out.find(":CONSOLE"), std::string::npos) << what << ": console output\n" << r.out.substr(0, 4000);
    return r.out;
  }
  void ExpectScreenshot(const std::string& html, const std::string& png, std::uintmax_t min_bytes) {
    auto r = RunCommand(Browser("--window-size=1100,1600 --screenshot=" + png + " file://" + html));
    ASSERT_TRUE(fs::exists(png)) << r.out;
    EXPECT_GT(fs::file_size(png), min_bytes) << png << " is nearly empty: no plots drawn?";
  }
  std::string Benchctl(const std::string& args, int expect = 0) {
    auto r = RunCommand(std::string(VB_BENCHCTL) + " " + args + " --db " + dir_ + "/local.db");
    EXPECT_EQ(r.exit_code, expect) << args << "\n" << r.out;
    return r.out;
  }

  std::string chromium_, dir_;
  int browsers_ = 0;
};

TEST_F(HeadlessReport, BatchRunRegressionAndDiagnosisPagesRenderWithoutErrors) {
  const std::string suites = std::string(VB_SOURCE_DIR) + "/examples/suites/";
  // A suite run: batch 1 (PI and hysteresis repeats, a 3-point static map) and regression result 1.
  Benchctl("regress " + suites + "ci.json --baseline " + suites + "ci-baseline.json --local");
  Benchctl("report --batch 1 --html " + dir_ + "/batch.html");
  Benchctl("report --run 1 --html " + dir_ + "/run.html");
  Benchctl("report --regress 1 --html " + dir_ + "/regress.html");
  const std::string fixtures = std::string(VB_SOURCE_DIR) + "/tests/report/";
  Benchctl("report --diagnosis " + fixtures + "diagnosis_fixture.json --html " + dir_ + "/diag.html");
  Benchctl("report --diagnosis " + fixtures + "diagnosis_partial.json --html " + dir_ + "/partial.html");
  for (const char* page : {"run", "regress", "partial"}) ExpectRenders(dir_ + "/" + page + ".html", page);
  // The batch page: meta, note, static map, comparison table, Pareto scatter, traces: 2 runs drawn x 3 panels,
  // the other 7 collapsed but there.
  const std::string batch = ExpectRenders(dir_ + "/batch.html", "batch");
  EXPECT_NE(batch.find("id=\"vb-status\">rendered-ok: 6 sections, 8 plots"), std::string::npos)
      << batch.substr(0, 2000);
  EXPECT_NE(batch.find("Runs, conditions and specs"), std::string::npos);
  EXPECT_NE(batch.find("Static map"), std::string::npos);
  // Every chart is the dashboard's (web/static/charts.js over dygraphs): 8 of them (static map, Pareto scatter,
  // 2 runs x 3 traces), each with its SVG and PNG buttons and its legend below; canvases drawn; axes in SI-prefixed
  // units from the shared formatter (the traces' time in ms, their position in µm).
  EXPECT_EQ(Count(batch, "class=\"vb-plot\""), 8u);
  EXPECT_EQ(Count(batch, "class=\"link dl-svg\""), 8u);
  EXPECT_EQ(Count(batch, "class=\"link dl-png\""), 8u);
  EXPECT_EQ(Count(batch, "class=\"vb-legend\""), 8u);
  EXPECT_GE(Count(batch, "<canvas"), 16u);
  EXPECT_NE(batch.find("dygraph-axis-label"), std::string::npos) << "dygraphs drew the axes";
  EXPECT_NE(batch.find(">t [ms]<"), std::string::npos) << "time axis prefixed by the shared formatter";
  EXPECT_NE(batch.find(">position [µm]<"), std::string::npos) << "position axis prefixed by the shared formatter";
  // The Pareto scatter as the Compare page draws it: each case labelled beside its point.
  EXPECT_NE(batch.find("vb-chart pareto"), std::string::npos);
  EXPECT_GE(Count(batch, "class=\"vb-point-label\""), 2u);
  EXPECT_EQ(Count(batch, "<details"), 10u) << "9 runs, every one reachable, and the specs";
  // The diagnosis page: summary, shares, per-phase table, ranking, one overlay of three curves.
  const std::string diag = ExpectRenders(dir_ + "/diag.html", "diag");
  // ... and under it the residual, measured - nominal (before) and measured - fitted (after), as the dashboard shows it.
  EXPECT_NE(diag.find("id=\"vb-status\">rendered-ok: 5 sections, 3 plots"), std::string::npos) << diag.substr(0, 2000);
  EXPECT_NE(diag.find("residual: measured − model"), std::string::npos);
  EXPECT_NE(diag.find(">measured − nominal (before)<"), std::string::npos);
  EXPECT_NE(diag.find(">measured − fitted (after)<"), std::string::npos);
  ExpectScreenshot(dir_ + "/batch.html", dir_ + "/batch.png", 40000);
}

TEST_F(HeadlessReport, ComparedLawsAreOverlaidAndPagesFitALaptopScreen) {
  // Seed 001's four current laws, then seed 000's static map (fig8 and fig9): batches 1 and 2.
  const std::string examples = std::string(VB_SOURCE_DIR) + "/examples/";
  Benchctl("run --local " + examples + "compare-current-controllers.json");
  Benchctl("report --batch 1 --html " + dir_ + "/current.html --svg " + dir_ + "/svg --png " + dir_ + "/png");
  const std::string page = ExpectRenders(dir_ + "/current.html", "current laws");
  EXPECT_NE(page.find("The compared laws on shared axes"), std::string::npos);
  EXPECT_NE(page.find("class=\"band\""), std::string::npos) << "the metric window is marked";
  EXPECT_NE(page.find("Tracking error over the metric window"), std::string::npos);
  EXPECT_NE(page.find("driver loss [mW]"), std::string::npos) << "axes carry units";
  EXPECT_NE(page.find("UTC"), std::string::npos) << "timestamps on the page";
  EXPECT_NE(page.find("supply_V = 24"), std::string::npos) << "conditions on the page";
  EXPECT_EQ(page.find("rendered-ok: 1"), std::string::npos);
  // Each law in its colour of every page (charts.js LAW_COLORS: PI green, #2ca02c), the table's swatch included.
  EXPECT_EQ(Count(page, "<i class=\"swatch\""), 4u);
  EXPECT_NE(page.find("<i class=\"swatch\" style=\"background: rgb(44, 160, 44);\"></i>pi</td>"), std::string::npos);
  EXPECT_NE(page.find("<i class=\"swatch\" style=\"background: rgb(255, 127, 14);\"></i>hysteresis</td>"), std::string::npos);
  for (const char* size : {"1400,900", "1024,768"}) {
    auto r = RunCommand(Browser(std::string("--window-size=") + size + " --dump-dom file://" + dir_ + "/current.html"));
    EXPECT_NE(r.out.find("data-vb-overflow-px=\"0\""), std::string::npos) << "sideways overflow at " << size;
  }
  // --svg/--png: every drawn plot, overlays included, as files.
  size_t svgs = 0, pngs = 0;
  for (const auto& e : fs::directory_iterator(dir_ + "/svg")) svgs += e.path().extension() == ".svg";
  for (const auto& e : fs::directory_iterator(dir_ + "/png")) pngs += e.path().extension() == ".png" && fs::file_size(e.path()) > 2000;
  EXPECT_GE(svgs, 3u + 4u * 3u) << "scatter, 2 overlay panels, 4 runs x 3 trace panels";
  EXPECT_EQ(pngs, svgs);
  std::string overlay_file;
  for (const auto& e : fs::directory_iterator(dir_ + "/svg"))
    if (e.path().filename().string().rfind("02-the-compared-laws-on-shared-axes", 0) == 0) overlay_file = e.path();
  std::ifstream overlay(overlay_file);
  std::stringstream ss;
  ss << overlay.rdbuf();
  EXPECT_NE(ss.str().find("xmlns=\"http://www.w3.org/2000/svg\""), std::string::npos) << ss.str().substr(0, 300);
  EXPECT_GE(Count(ss.str(), "<polyline"), 5u) << "four laws and the reference on one axis";

  Benchctl("run --local " + examples + "static-map.json");
  Benchctl("report --batch 2 --html " + dir_ + "/map.html --max-traces 3");
  const std::string map = ExpectRenders(dir_ + "/map.html", "static map");
  EXPECT_NE(map.find("Static map, static-map/fig8"), std::string::npos);
  EXPECT_NE(map.find("Static map, static-map/fig9"), std::string::npos);
  EXPECT_NE(map.find("duty [%]"), std::string::npos);
  EXPECT_NE(map.find("4 bar"), std::string::npos);
  auto r = RunCommand(Browser("--window-size=1024,768 --dump-dom file://" + dir_ + "/map.html"));
  EXPECT_NE(r.out.find("data-vb-overflow-px=\"0\""), std::string::npos) << "sideways overflow at 1024 px";
}

TEST_F(HeadlessReport, ABrokenPageIsCaught) {
  // The checks above can fail: a page whose script throws never writes the marker, and the console shows it.
  const std::string html = dir_ + "/broken.html";
  std::ofstream(html) << "<html><body><div id=\"vb-status\">rendering</div><script>"
                         "window.onerror = function (m) { document.getElementById('vb-status').textContent = "
                         "'render-error: ' + m; }; undefinedFunction();</script></body></html>";
  auto r = RunCommand(Browser("--dump-dom file://" + html));
  EXPECT_EQ(r.out.find("id=\"vb-status\">rendered-ok"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("id=\"vb-status\">render-error: "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(":CONSOLE"), std::string::npos) << r.out;
}

}  // namespace
