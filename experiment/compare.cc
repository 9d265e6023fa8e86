#include "experiment/compare.h"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "common/csv.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>

namespace vb::experiment {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

const std::vector<std::string>& DefaultColumns() {
  static const std::vector<std::string> cols = {"rmse",      "effort_l2",     "effort_rms",     "energy_J",
                                                "switches",  "iae",           "max_abs_error",  "overshoot",
                                                "settling_time_s", "opening_delay_s", "closing_delay_s",
                                                "mean_current_A"};
  return cols;
}

double Mean(const MetricStat& s) { return s.n > 0 ? s.mean : kNaN; }

}  // namespace

Comparison Compare(const std::vector<RunRecord>& runs) {
  Comparison c;
  c.columns = DefaultColumns();
  // Group by name (repeats of one configuration share it), in first-seen order.
  std::vector<CompareRow> rows;
  std::map<std::string, std::vector<const RunRecord*>> groups;
  for (const auto& r : runs) {
    if (groups.find(r.name) == groups.end()) {
      CompareRow row;
      row.name = r.name;
      row.controller = r.controller;
      rows.push_back(row);
    }
    groups[r.name].push_back(&r);
  }
  for (auto& row : rows) {
    const auto& members = groups[row.name];
    row.runs = static_cast<int>(members.size());
    for (const auto* r : members) row.failed += r->ok ? 0 : 1;
    for (const auto& col : c.columns) {
      MetricStat st;
      double sum = 0, sum2 = 0;
      for (const auto* r : members) {
        if (!r->ok) continue;
        auto it = r->metrics.find(col);
        if (it == r->metrics.end() || !std::isfinite(it->second)) continue;
        sum += it->second;
        sum2 += it->second * it->second;
        ++st.n;
      }
      if (st.n > 0) {
        st.mean = sum / st.n;
        st.spread = st.n > 1 ? std::sqrt(std::max(0.0, (sum2 - st.n * st.mean * st.mean) / (st.n - 1))) : 0.0;
      }
      row.metrics[col] = st;
    }
  }
  // Sort by mean RMSE (missing last), then rank: a row only gets a new rank when its RMSE is worse than the
  // previous rank's by more than their combined spread.
  std::stable_sort(rows.begin(), rows.end(), [&](const CompareRow& a, const CompareRow& b) {
    const double ea = Mean(a.metrics.at(c.rank_metric)), eb = Mean(b.metrics.at(c.rank_metric));
    if (std::isnan(ea)) return false;
    if (std::isnan(eb)) return true;
    return ea < eb;
  });
  int rank = 0;
  const CompareRow* anchor = nullptr;
  for (auto& row : rows) {
    const MetricStat& s = row.metrics.at(c.rank_metric);
    if (s.n == 0) {
      row.rank = 0;
      continue;
    }
    if (anchor == nullptr) {
      rank = 1;
      anchor = &row;
    } else {
      const MetricStat& a = anchor->metrics.at(c.rank_metric);
      if (s.mean - a.mean > s.spread + a.spread) {
        ++rank;
        anchor = &row;
      }
    }
    row.rank = rank;
  }
  // Pareto front in (rank metric, effort): minimise both.
  for (auto& row : rows) {
    const double e = Mean(row.metrics.at(c.rank_metric)), u = Mean(row.metrics.at(c.effort_metric));
    if (std::isnan(e) || std::isnan(u)) continue;
    bool dominated = false;
    for (const auto& other : rows) {
      const double eo = Mean(other.metrics.at(c.rank_metric)), uo = Mean(other.metrics.at(c.effort_metric));
      if (std::isnan(eo) || std::isnan(uo) || &other == &row) continue;
      if (eo <= e && uo <= u && (eo < e || uo < u)) {
        dominated = true;
        break;
      }
    }
    row.pareto = !dominated;
  }
  c.rows = std::move(rows);
  return c;
}

std::string ComparisonTable(const Comparison& c) {
  std::ostringstream os;
  size_t name_w = 4;
  for (const auto& r : c.rows) name_w = std::max(name_w, r.name.size());
  os << fmt::format("{:<4} {:<{}} {:<20} {:>4}", "rank", "name", name_w, "controller", "n");
  for (const auto& col : c.columns) os << fmt::format(" {:>15}", col);
  os << "  pareto\n";
  for (const auto& r : c.rows) {
    os << fmt::format("{:<4} {:<{}} {:<20} {:>4}", r.rank > 0 ? std::to_string(r.rank) : "-", r.name, name_w,
                      r.controller, r.runs);
    for (const auto& col : c.columns) {
      const MetricStat& s = r.metrics.at(col);
      if (s.n == 0) {
        os << fmt::format(" {:>15}", "-");
      } else if (s.n > 1) {
        os << fmt::format(" {:8.4g}±{:<6.2g}", s.mean, s.spread);
      } else {
        os << fmt::format(" {:15.6g}", s.mean);
      }
    }
    os << (r.pareto ? "  *" : "") << (r.failed > 0 ? "  (" + std::to_string(r.failed) + " failed)" : "") << "\n";
  }
  os << "rank by " << c.rank_metric << " (rows within the repeat spread share a rank); * = Pareto-optimal in ("
     << c.rank_metric << ", " << c.effort_metric << ")\n";
  return os.str();
}

std::string ComparisonCsv(const Comparison& c) {
  std::ostringstream os;
  os << "rank,name,controller,runs,failed,pareto";
  for (const auto& col : c.columns) os << "," << col << "," << col << "_spread";
  os << "\n";
  os.precision(10);
  for (const auto& r : c.rows) {
    os << r.rank << "," << CsvQuoted(r.name) << "," << r.controller << "," << r.runs << "," << r.failed << ","
       << (r.pareto ? 1 : 0);
    for (const auto& col : c.columns) {
      const MetricStat& s = r.metrics.at(col);
      if (s.n == 0) {
        os << ",,";
      } else {
        os << "," << s.mean << "," << s.spread;
      }
    }
    os << "\n";
  }
  return os.str();
}

std::string ComparisonJson(const Comparison& c) {
  using Json = nlohmann::ordered_json;
  Json rows = Json::array();
  for (const auto& r : c.rows) {
    Json m = Json::object();
    for (const auto& col : c.columns) {
      auto it = r.metrics.find(col);
      m[col] = it == r.metrics.end() || it->second.n == 0
                   ? Json(nullptr)
                   : Json{{"mean", it->second.mean}, {"spread", it->second.spread}, {"n", it->second.n}};
    }
    rows.push_back({{"rank", r.rank},
                    {"name", r.name},
                    {"controller", r.controller},
                    {"runs", r.runs},
                    {"failed", r.failed},
                    {"pareto", r.pareto},
                    {"metrics", m}});
  }
  return Json{{"rank_metric", c.rank_metric}, {"effort_metric", c.effort_metric}, {"columns", c.columns}, {"rows", rows}}
             .dump(2) + "\n";
}

}  // namespace vb::experiment
