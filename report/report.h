// Self-contained HTML reports (docs/report.md): one file, no network access, the data as JSON inside it and a
// small vanilla-JS renderer (report/page.cc) that draws inline SVG: zoomable traces, an RMSE-vs-effort scatter
// with the Pareto front, static maps, regression tables and gap-diagnosis overlays.
//
// A report is a list of sections (JSON objects with a "kind"); the builders below make them from our types.
// The page writes "rendered-ok" into #vb-status once every section drew without an exception, and
// "render-error: ..." if anything threw (window.onerror): the headless-browser test reads that marker.
#pragma once

#include <nlohmann/json.hpp>

#include <map>
#include <string>

#include "common/run_key.h"
#include <vector>

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

// Min/max decimation to at most ~max_points per channel (peaks survive), keeping time stamps.
Json TraceSection(const std::vector<TraceData>& traces, std::size_t max_points = 4000);
// Metrics table plus the RMSE-vs-effort scatter with the Pareto front (rows without both metrics are left out).
Json ComparisonSections(const experiment::Comparison& c, const std::string& title);
// A run's metrics as a two-column table.
Json MetricsSection(const std::string& title, const std::vector<std::pair<std::string, double>>& metrics);

// Static map (seed 000 Figs. 8-9): swept runs with mean_position_pct; x is the last sweep axis of their key,
// one line per combination of the others (repeats averaged). Returns null when the runs are not a sweep.
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

// The page: title, sections (an array of section objects).
std::string RenderHtml(const std::string& title, const Json& sections);

}  // namespace vb::report
