// Controller comparison over a set of runs: metrics side by side, mean and spread over repeats, a ranking by
// RMSE in which differences inside the repeat spread are not ranked, and the Pareto front in (RMSE, effort).
#pragma once

#include <map>
#include <string>
#include <vector>

namespace vb::experiment {

struct RunRecord {
  std::string name;                      // the case (RunKey::CaseName): repeats share it
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
  std::string name;
  std::string controller;
  int runs = 0;
  int failed = 0;
  std::map<std::string, MetricStat> metrics;
  int rank = 0;          // 1 = best RMSE; rows whose RMSE differs by less than the spread share a rank
  bool pareto = false;   // not dominated in (rmse, effort_l2)
};

struct Comparison {
  std::string rank_metric = "rmse";
  std::string effort_metric = "effort_l2";
  std::vector<std::string> columns;      // metrics shown, in order
  std::vector<CompareRow> rows;          // sorted by rank
};

Comparison Compare(const std::vector<RunRecord>& runs);

// The renderings every command uses, local or remote: people (fixed-width table), scripts (CSV, JSON:
// {rank_metric, effort_metric, columns, rows: [{rank, name, controller, runs, failed, pareto,
// metrics: {column: {mean, spread, n} or null}}]}).
std::string ComparisonTable(const Comparison& c);
std::string ComparisonCsv(const Comparison& c);
std::string ComparisonJson(const Comparison& c);

}  // namespace vb::experiment
