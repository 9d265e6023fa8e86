// Self-contained HTML reports (docs/report.md): one file, no network access, the data as JSON inside it, Debian's
// dygraphs and the web dashboard's chart code (web/static/format.js, charts.js) inlined: traces, overlays, the
// RMSE-vs-effort scatter, static maps and gap-diagnosis overlays are drawn as on the dashboard; report/page.cc
// hands each section to that code (and draws the regression's bars itself).
//
// A report is a list of sections (JSON objects with a "kind"); the builders below make them from our types.
// The page writes "rendered-ok" into #vb-status once every section drew without an exception, and
// "render-error: ..." if anything threw (window.onerror): the headless-browser test reads that marker.
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "common/run_key.h"
#include "common/run_status.h"
#include "common/status.h"

#include "experiment/compare.h"

namespace vb::report {

using Json = nlohmann::ordered_json;

// One run's channels, uniformly sampled. Channels used: gate, i_A, ref, x_m, v_coil_V (others ignored).
struct TraceData {
  std::string label;                                // e.g. "run 12: compare/pi"
  std::string controlled;                           // "current", "position" or "" (where ref goes)
  double t0_s = 0.0, sample_period_s = 0.0;
  std::map<std::string, std::vector<double>> channels;
};

// Min/max decimation to at most ~max_points per channel (peaks survive), keeping time stamps. Each run is a
// collapsible block (the first `open` drawn at once, the others when opened: every run of a batch reachable).
Json TraceSection(const std::vector<TraceData>& traces, std::size_t max_points = 4000, std::size_t open = 4);
// Metrics table plus the RMSE-vs-effort scatter with the Pareto front (rows without both metrics are left out).
Json ComparisonSections(const experiment::Comparison& c, const std::string& title);
// A run's metrics as a two-column table.
Json MetricsSection(const std::string& title, const std::vector<std::pair<std::string, double>>& metrics);

// Static map (seed 000 Figs. 8-9): swept runs with mean_position_pct, one plot per spec name (fig8, fig9): x is
// the duty axis in % (else the last sweep axis), one curve per value of the other axes (pressure in bar,
// frequency in Hz; repeats averaged). An empty array when the runs are not a sweep.
struct MapPoint {
  RunKey key;
  double value = 0.0;  // mean_position_pct
};
Json StaticMapSection(const std::vector<MapPoint>& points, const std::string& metric_label);

// A regression result (regress::ResultToJson) as tables and a chart of each change against its allowance.
Json RegressionSections(const Json& result);
// A gap diagnosis (benchctl diagnose --json): whatever of model, noise_floor_A, gap, where, ranking, verdict and
// overlays is present; missing or malformed parts are left out with a note, never an error.
Json DiagnosisSections(const Json& diagnosis);

// A stored run as a report sees it (either backend): identity, spec, times, metrics and (optionally) its trace.
struct RunInfo {
  std::int64_t id = 0;
  RunKey key;
  std::string controller;
  RunStatus status = RunStatus::kDone;    // the run's outcome (common/run_status.h)
  std::map<std::string, double> metrics;
  std::string spec_json;                 // the single-run spec ("" = not known)
  double submitted_unix_s = 0.0, started_unix_s = 0.0, finished_unix_s = 0.0;
  TraceData trace;                       // no channels = not fetched
};

// The header every run and batch page starts with: where the runs are, when they ran and when the page was
// made (UTC), the conditions (bench, driver, supply, pressure, duration, metric window) and the spec itself.
Json MetaSection(const std::string& where, const std::vector<RunInfo>& runs);
// Overlays of the compared runs on shared axes: the controlled variable with its reference (metric window
// shaded) and the tracking error over the metric window. Null when the runs have no reference or no trace.
Json OverlaySection(const std::vector<RunInfo>& runs, std::size_t max_points = 2000);
// The batch page: meta, comparison table (the terminal table's columns and units), the Pareto scatter,
// the static map (seed 000 Figs. 8-9: position against duty, a curve per pressure or frequency), the overlays
// and every run's traces.
Json BatchSections(const std::string& where, std::int64_t batch, const std::vector<RunInfo>& runs);
// The run page: meta, traces, metrics.
Json RunSections(const std::string& where, const RunInfo& run);

// The page: title, sections (an array of section objects).
std::string RenderHtml(const std::string& title, const Json& sections);

// Every plot of a written page as NN-<heading>.svg in svg_dir and/or .png in png_dir ("" = not wanted), drawn
// by headless chromium (report/export.cc). Returns the files written; Unavailable without chromium.
StatusOr<std::vector<std::string>> ExportPlots(const std::string& html_path, const std::string& svg_dir,
                                               const std::string& png_dir);

}  // namespace vb::report
