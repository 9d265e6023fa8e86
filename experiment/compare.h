// Controller comparison over a set of runs: metrics side by side, mean and spread over repeats, a ranking by
// RMSE in which differences inside the repeat spread are not ranked, and the Pareto front in (RMSE, effort),
// with the effort chosen per experiment kind (docs/metrics.md "Effort per experiment kind").
//
// The renderings every command uses, local or remote: people (a table that fits 120 columns, units in every
// header, SI prefixes per column: docs/comparison.md "Reading the table"), scripts (CSV and JSON with the full
// metric names in SI units).
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "common/run_key.h"

namespace vb::experiment {

struct RunRecord {
  RunKey key;                            // the run's identity; repeats (same key but for `repeat`) share a row
  std::int64_t run_id = 0;               // the stored run (0: not stored, e.g. `compare RESULTS.json`)
  std::string controller;
  bool ok = true;
  std::map<std::string, double> metrics;
};

struct MetricStat {
  double mean = 0.0;
  double spread = 0.0;  // sample standard deviation over repeats (0 for one run)
  int n = 0;            // finite values
};

struct CompareRow {
  RunKey key;                            // the case: name and sweep point as fields (repeat -1)
  std::vector<std::int64_t> run_ids;     // the stored runs the row aggregates (those with an id), in input order
  std::string name;                      // key.CaseName(), for people and scripts; nothing parses it back
  std::string controller;
  int runs = 0;
  int failed = 0;
  std::map<std::string, MetricStat> metrics;
  int rank = 0;          // 1 = best RMSE; rows whose RMSE differs by less than the spread share a rank
  bool pareto = false;   // not dominated in (rank_metric, effort_metric)
};

// What was compared, read from the laws of the rows (every row the same class, else kGeneric).
enum class ExperimentKind {
  kGeneric,
  kCurrentLaws,   // hysteresis, PI, predictive, fuzzy current laws, peak-and-hold: seed 001
  kPositionLaws,  // cascade PI, sliding mode: seed 002
  kDither,        // seed 003's planned PWM
  kOpenLoop,      // open-loop PWM: seed 000's static map
};
ExperimentKind KindOf(const std::vector<std::string>& controllers);
// A single run's two headline metrics as a comparison of its law shows them (rank metric "rmse" and the
// comparison's effort metric: driver loss for current laws, ||u||2 for position laws, ||v||2 otherwise), with
// the CLI's label and SI unit: what a list of runs shows so that its columns are the Compare page's.
struct HeadlineMetric {
  std::string metric;  // e.g. "driver_loss_W"
  std::string label;   // e.g. "driver loss"
  std::string unit;    // e.g. "W" (SI, before any prefix)
};
HeadlineMetric RankMetricOf(const std::string& controller);
HeadlineMetric EffortMetricOf(const std::string& controller);
const char* KindName(ExperimentKind kind);

struct Comparison {
  std::string rank_metric = "rmse";
  std::string effort_metric = "effort_l2";  // per kind: driver_loss_W (current laws), effort_u_l2 (position)
  std::vector<std::string> columns;          // every metric some run has, MetricList order then by name
  std::vector<CompareRow> rows;              // sorted by rank, then first-seen order
};

Comparison Compare(const std::vector<RunRecord>& runs);

// A metric's SI unit as its JSON value carries it ("A" or "m" for rmse by the law, "V s^0.5", "1" for ratios
// and counts, "" when unknown): for listings that print SI values.
std::string SiUnit(const std::string& metric, const std::string& controller);
// A metric's CSV column: its name when the name carries its unit (mean_current_A, energy_J) or it has none
// (overshoot, switches), otherwise the name with its SI unit appended: rmse -> rmse_A (rmse_m for position
// laws), iae -> iae_A_s, effort_l2 -> effort_l2_V_sqrt_s (python/valvebench/units.py metric_column).
std::string MetricColumnName(const std::string& metric, const std::string& controller);

// Which columns a table shows.
struct TableOptions {
  std::vector<std::string> metrics;  // --metrics a,b: exactly these (full names), in this order
  bool wide = false;                 // --wide: every metric that has a value in some row
};

// The columns a table shows for these options: the kind's defaults, or the asked ones. Unknown names in
// `metrics` are an InvalidArgument naming them and the known ones (returned as the message; empty = fine).
std::string CheckTableOptions(const Comparison& c, const TableOptions& options);

// For people: fits 120 columns with the defaults (tested). Static-map sweeps (open-loop runs with
// mean_position_pct) print seed 000 Figs. 8-9's form: position against duty, one column per other sweep value.
// Dither runs (seed 003) print the paper's Table I beside the planned and achieved values.
std::string ComparisonTable(const Comparison& c, const TableOptions& options = {});
// The table's cells for other renderers (the HTML report): the same columns, headers and units as the text
// table's long form (one row per case, also for static maps).
struct TableGrid {
  std::vector<std::string> headers;
  std::vector<bool> left;                     // left-aligned (text) columns
  std::vector<std::vector<std::string>> rows;
};
TableGrid ComparisonGrid(const Comparison& c, const TableOptions& options = {});
// How a metric is shown in these rows: "driver loss [mW]" and the factor from its SI value (1e3).
struct MetricDisplay {
  std::string header;
  double scale = 1.0;
};
MetricDisplay DisplayOf(const Comparison& c, const std::string& metric);

// How a column is shown, for renderers that format the cells themselves (the web dashboard): the choice the
// text table makes (SI prefix on the column's largest value, 4 significant digits), so every view agrees.
struct ColumnDisplay {
  std::string label;       // "RMSE"
  std::string unit;        // with its prefix, "mA"; "" = none
  std::string header;      // "RMSE [mA]"
  double scale = 1.0;      // SI value * scale = the shown number
  int decimals = 2;        // of the mean
  int spread_decimals = 2; // of the spread
};
ColumnDisplay MetricColumnDisplay(const Comparison& c, const std::string& metric);
// A sweep axis (a spec field path such as "controller.open_loop_pwm.duty") over the rows' values.
ColumnDisplay SweepColumnDisplay(const std::string& field, const std::vector<double>& values);
// The metrics the text table shows by default for these rows (the kind's defaults that some row has).
std::vector<std::string> DefaultMetricColumns(const Comparison& c);
// The SI prefixes columns choose from, largest first: symbol and SI value * scale = value in the prefixed unit.
// A column takes the first whose scale puts its largest magnitude at 1 or above.
struct SiPrefix {
  std::string symbol;
  double scale;
};
std::vector<SiPrefix> SiPrefixes();
// A law's short name for people ("PI" for pi_current).
std::string LawName(const std::string& controller);

// For scripts: one row per case, the sweep coordinates as columns (full field paths), every metric and its
// spread in SI units with full names.
std::string ComparisonCsv(const Comparison& c);
// {kind, rank_metric, effort_metric, columns, rows: [{rank, name, controller, runs, failed, pareto,
// key: {name, sweep: [{field, value}]}, run_ids: [...], sweep: {field: value}, metrics: {column: {mean, spread, n} or null}}]}.
std::string ComparisonJson(const Comparison& c);
// The service's comparison (a valvebench::v1::CompareRunsResponse; a template, so that this library needs no
// gRPC code) as the Comparison every renderer above takes: benchctl's remote commands and the web's comparison
// downloads write the same files.
template <class CompareRunsResponse>
Comparison ComparisonFromProto(const CompareRunsResponse& cmp) {
  Comparison c;
  c.rank_metric = cmp.rank_metric();
  c.effort_metric = cmp.effort_metric();
  c.columns.assign(cmp.columns().begin(), cmp.columns().end());
  for (const auto& r : cmp.rows()) {
    CompareRow row;
    // The case's identity as fields; a row from a server older than CompareRow.key is only its name.
    if (r.has_key()) {
      row.key = RunKey{r.key().name(), {}, r.key().repeat()};
      for (const auto& p : r.key().sweep()) row.key.sweep.push_back({p.field(), p.value()});
    } else {
      row.key = NamedRun(r.name());
    }
    row.run_ids.assign(r.run_ids().begin(), r.run_ids().end());
    row.name = r.name();
    row.controller = r.controller();
    row.runs = r.runs();
    row.failed = r.failed();
    row.rank = r.rank();
    row.pareto = r.pareto();
    for (const auto& col : c.columns) {
      MetricStat st;
      auto it = r.metrics().find(col);
      if (it != r.metrics().end()) st = {it->second.mean(), it->second.spread(), it->second.n()};
      row.metrics[col] = st;
    }
    c.rows.push_back(std::move(row));
  }
  return c;
}


}  // namespace vb::experiment
