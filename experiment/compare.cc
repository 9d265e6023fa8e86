#include "experiment/compare.h"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "common/csv.h"
#include "common/units.h"
#include "experiment/metrics.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <set>
#include <sstream>

namespace vb::experiment {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr size_t kTableWidth = 120;  // docs/comparison.md: the default table fits a 120-column terminal

double Mean(const MetricStat& s) { return s.n > 0 ? s.mean : kNaN; }

const MetricStat* Stat(const CompareRow& r, const std::string& col) {
  auto it = r.metrics.find(col);
  return it == r.metrics.end() ? nullptr : &it->second;
}

// ---- what each metric is called in a header, and in which unit -------------------------------------------

struct MetricView {
  std::string label;   // short header label
  std::string unit;    // SI base unit the value is in after `factor` ("" = dimensionless; "%" = percent)
  double factor = 1;   // value in the JSON's SI unit * factor = value in `unit`
  bool prefix = true;  // choose an SI prefix per column
  int decimals = -1;   // fixed decimals (-1: 4 significant digits on the column's largest value)
};

// docs/metrics.md has the definitions; the controlled variable's unit is A for current laws, m for position.
MetricView ViewOf(const std::string& name, ExperimentKind kind) {
  const std::string y = kind == ExperimentKind::kPositionLaws ? "m" : "A";
  if (name == "rmse") return {"RMSE", y};
  if (name == "iae") return {"IAE", y + " s"};
  if (name == "max_abs_error") return {"max|e|", y};
  if (name == "overshoot") return {"overshoot", "%", 100, false};
  if (name == "settling_time_s") return {"settle", "s"};
  if (name == "effort_l2") return {"||v||2", "V s^0.5"};
  if (name == "effort_rms") return {"v_rms", "V"};
  if (name == "energy_J") return {"energy", "J"};
  if (name == "switches") return {"switches", "", 1, false};
  if (name == "mean_current_A") return {"mean i", "A"};
  if (name == "opening_delay_s") return {"open delay", "s"};
  if (name == "closing_delay_s") return {"close delay", "s"};
  if (name == "mean_position_m") return {"mean x", "m"};
  if (name == "mean_position_pct") return {"mean x", "%", 1, false};
  if (name == "mean_flow_kg_per_s") return {"flow", "kg/s"};  // prefixed as a gram: mg/s, g/s
  if (name == "switching_rate_Hz") return {"sw rate", "Hz"};
  if (name == "diode_loss_W") return {"diode loss", "W"};
  if (name == "switching_loss_W") return {"sw loss", "W"};
  if (name == "driver_loss_W") return {"driver loss", "W"};
  if (name == "effort_u_l2") return {"||u||2", "N s^0.5"};
  // Seed 003 Table I prints f and D with two decimals: ours beside it with as many.
  if (name == "pwm_frequency_Hz") return {"f_PWM", "Hz", 1, false, 2};
  if (name == "pwm_duty") return {"duty", "%", 100, false, 2};
  if (name == "ripple_pp_A") return {"I_amp p-p", "A"};
  if (name == "ripple_mid_A") return {"I_avg", "A"};
  // Anything else (a metric from a newer server): the name itself, its unit from the name's suffix.
  for (const auto& [suffix, unit] : std::vector<std::pair<std::string, std::string>>{
           {"_pct", "%"}, {"_Hz", "Hz"}, {"_J", "J"}, {"_W", "W"}, {"_V", "V"}, {"_A", "A"}, {"_m", "m"},
           {"_s", "s"}, {"_Pa", "Pa"}}) {
    if (name.size() > suffix.size() && name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0)
      return {name.substr(0, name.size() - suffix.size()), unit, 1, unit != "%"};
  }
  return {name, "", 1, false};
}

// The columns a kind shows by default: what the laws trade (docs/metrics.md "Effort per experiment kind").
std::vector<std::string> DefaultColumns(ExperimentKind kind) {
  switch (kind) {
    case ExperimentKind::kCurrentLaws:
      return {"rmse", "max_abs_error", "overshoot", "settling_time_s", "switching_rate_Hz", "switching_loss_W",
              "diode_loss_W", "driver_loss_W"};
    case ExperimentKind::kPositionLaws:
      return {"rmse", "overshoot", "settling_time_s", "effort_u_l2", "effort_l2"};
    case ExperimentKind::kDither:
      return {"pwm_frequency_Hz", "pwm_duty", "ripple_mid_A", "ripple_pp_A"};
    case ExperimentKind::kOpenLoop:
      return {"mean_position_pct", "mean_current_A", "opening_delay_s", "closing_delay_s", "mean_flow_kg_per_s"};
    case ExperimentKind::kGeneric:
      break;
  }
  return {"rmse", "effort_l2", "energy_J", "switching_rate_Hz", "mean_current_A", "mean_position_pct"};
}

std::string EffortOf(ExperimentKind kind) {
  switch (kind) {
    case ExperimentKind::kCurrentLaws: return "driver_loss_W";
    case ExperimentKind::kPositionLaws: return "effort_u_l2";
    default: return "effort_l2";
  }
}

// ---- text layout ------------------------------------------------------------------------------------------

size_t Width(const std::string& s) {  // display width: UTF-8 code points
  size_t w = 0;
  for (unsigned char ch : s) w += (ch & 0xC0) != 0x80;
  return w;
}
std::string PadLeft(const std::string& s, size_t w) { return std::string(w > Width(s) ? w - Width(s) : 0, ' ') + s; }
std::string PadRight(const std::string& s, size_t w) { return s + std::string(w > Width(s) ? w - Width(s) : 0, ' '); }

// The unit a view shows for values of largest magnitude `max_abs` (in the view's unit, after its factor): the
// one rule of common/units.h (compound units prefixed on their first factor: mm^2, mg/s), or the unit as it is
// for views without a prefix (%, counts).
UnitChoice Shown(const MetricView& v, double max_abs) {
  return v.prefix ? ChooseUnit(max_abs, v.unit) : UnitChoice{v.unit, 1.0};
}

// Decimals that give the column's largest value 4 significant digits (at most 4 decimals, none for counts).
int DecimalsFor(double max_abs, bool integer) {
  if (integer) return 0;
  if (!(max_abs > 0) || !std::isfinite(max_abs)) return 2;
  const int digits_before = std::max(1, static_cast<int>(std::floor(std::log10(max_abs))) + 1);
  return std::clamp(4 - digits_before, 0, 4);
}

// One column of a text table: its header and its cells for every row, already scaled and formatted.
struct TextColumn {
  std::string header;
  std::vector<std::string> cells;
  bool left = false;
};

// How a numeric column from per-row stats in `unit` (after factor) is shown: the SI prefix and the decimals
// chosen on the column (the one rule for the CLI's tables, the HTML report and the web page).
ColumnDisplay ChooseDisplay(const std::string& label, const MetricView& v, const std::vector<MetricStat>& stats) {
  double max_abs = 0;
  bool integer = v.unit.empty();
  for (const auto& s : stats)
    if (s.n > 0) {
      max_abs = std::max(max_abs, std::abs(s.mean * v.factor));
      if (s.mean != std::round(s.mean)) integer = false;
    }
  const UnitChoice p = Shown(v, max_abs);
  ColumnDisplay d;
  d.label = label;
  d.unit = v.unit.empty() ? "" : p.unit;
  d.header = d.unit.empty() ? label : label + " [" + d.unit + "]";
  d.scale = v.factor * p.scale;
  d.decimals = v.decimals >= 0 ? v.decimals : DecimalsFor(max_abs * p.scale, integer);
  d.spread_decimals = std::max(d.decimals, 1);
  return d;
}

// A numeric column from per-row stats in `unit` (after factor): SI prefix and decimals chosen on the column.
TextColumn NumericColumn(const std::string& label, const MetricView& v, const std::vector<MetricStat>& stats) {
  const ColumnDisplay d = ChooseDisplay(label, v, stats);
  TextColumn col;
  col.header = d.header;
  for (const auto& s : stats) {
    if (s.n == 0) {
      col.cells.push_back("-");
    } else {
      std::string cell = fmt::format("{:.{}f}", s.mean * d.scale, d.decimals);
      if (s.n > 1) cell += fmt::format("±{:.{}f}", s.spread * d.scale, d.spread_decimals);
      col.cells.push_back(cell);
    }
  }
  return col;
}

std::string Render(const std::vector<TextColumn>& cols, size_t rows) {
  std::vector<size_t> w;
  for (const auto& c : cols) {
    size_t x = Width(c.header);
    for (const auto& cell : c.cells) x = std::max(x, Width(cell));
    w.push_back(x);
  }
  std::ostringstream os;
  auto line = [&](const std::function<std::string(size_t)>& text, const std::function<bool(size_t)>& left) {
    std::string out;
    for (size_t j = 0; j < cols.size(); ++j) {
      if (j > 0) out += "  ";
      out += left(j) ? PadRight(text(j), w[j]) : PadLeft(text(j), w[j]);
    }
    while (!out.empty() && out.back() == ' ') out.pop_back();
    os << out << "\n";
  };
  line([&](size_t j) { return cols[j].header; }, [&](size_t j) { return cols[j].left; });
  for (size_t i = 0; i < rows; ++i)
    line([&](size_t j) { return cols[j].cells[i]; }, [&](size_t j) { return cols[j].left; });
  return os.str();
}

// The part of every row name up to a '/' that all rows share ("compare-current-controllers/").
std::string CommonPrefix(const std::vector<std::string>& names) {
  if (names.size() < 2) {
    if (names.empty()) return "";
    const size_t slash = names[0].find('/');
    return slash == std::string::npos ? "" : names[0].substr(0, slash + 1);
  }
  std::string p = names[0];
  for (const auto& n : names) {
    size_t k = 0;
    while (k < p.size() && k < n.size() && p[k] == n[k]) ++k;
    p.resize(k);
  }
  const size_t slash = p.rfind('/');
  return slash == std::string::npos ? "" : p.substr(0, slash + 1);
}

std::string Leaf(const std::string& field) {
  const size_t dot = field.rfind('.');
  return dot == std::string::npos ? field : field.substr(dot + 1);
}

// A sweep axis as a column: the leaf of its field path, its unit from the suffix, prefixed per column.
MetricView SweepView(const std::string& field) {
  MetricView v = ViewOf(Leaf(field), ExperimentKind::kGeneric);
  if (Leaf(field) == "duty") v = {"duty", "%", 100, false};
  if (Leaf(field) == "average_current_A") v.label = "I_avg set";  // seed 003's requested I_avg
  return v;
}
std::vector<MetricStat> SweepStats(const std::vector<double>& values) {
  std::vector<MetricStat> stats;
  for (double x : values) stats.push_back(std::isnan(x) ? MetricStat{} : MetricStat{x, 0, 1});
  return stats;
}
TextColumn SweepColumn(const std::string& field, const std::vector<double>& values) {
  const MetricView v = SweepView(field);
  return NumericColumn(v.label, v, SweepStats(values));
}

std::string FormatSweepValue(const std::string& field, double value, double column_max) {
  MetricView v = ViewOf(Leaf(field), ExperimentKind::kGeneric);
  if (Leaf(field) == "duty") v = {"duty", "%", 100, false};
  const UnitChoice p = Shown(v, column_max * v.factor);
  const double x = value * v.factor * p.scale;
  const std::string num = fmt::format("{}", std::round(x * 1e6) / 1e6);
  return v.unit.empty() ? v.label + "=" + num : num + " " + p.unit;
}

// Seed 003 Table I (exact method; coil 28.5 ohm, 0.33 H, 24 V; I_amp = 0.05 A p-p), docs/dither.md: the
// paper's printed (f, D) for each requested I_avg. 333.99 Hz is the paper's typo for 333.00 (docs/dither.md).
struct TableIRow {
  double i_avg_A, i_amp_A, f_Hz, duty;
};
constexpr TableIRow kSeed003TableI[] = {{0.1, 0.05, 149.36, 0.1166},
                                        {0.3, 0.05, 333.99, 0.3559},
                                        {0.5, 0.05, 350.36, 0.5940},
                                        {0.7, 0.05, 202.25, 0.8327}};

// The Table I row a dither run reproduces: its requested average (the sweep value) or, without one, the row
// whose (f, D) is within 1 % of what the planner chose.
const TableIRow* TableIFor(const RunKey& key, const CompareRow& row) {
  for (const auto& c : key.sweep)
    if (Leaf(c.field) == "average_current_A")
      for (const auto& t : kSeed003TableI)
        if (std::abs(c.value - t.i_avg_A) < 1e-9) return &t;
  const MetricStat* f = Stat(row, "pwm_frequency_Hz");
  const MetricStat* d = Stat(row, "pwm_duty");
  if (f == nullptr || d == nullptr || f->n == 0 || d->n == 0) return nullptr;
  for (const auto& t : kSeed003TableI)
    if (std::abs(f->mean - t.f_Hz) < 0.01 * t.f_Hz && std::abs(d->mean - t.duty) < 0.01 * t.duty) return &t;
  return nullptr;
}

// The law as people call it (the papers' names); JSON and CSV keep the spec's name.
std::string LawLabel(const std::string& controller) {
  static const std::map<std::string, std::string> kLabels = {
      {"hysteresis_current", "hysteresis"},   {"pi_current", "PI"},
      {"predictive_current", "predictive"},   {"fuzzy_current", "fuzzy"},
      {"cascade_pi_position", "cascade PI"},  {"sliding_mode_position", "sliding mode"},
      {"peak_and_hold", "peak and hold"},     {"dither_pwm", "dither (seed 003)"},
      {"open_loop_pwm", "open loop"}};
  auto it = kLabels.find(controller);
  return it == kLabels.end() ? controller : it->second;
}

std::vector<std::string> ShownColumns(const Comparison& c, ExperimentKind kind, const TableOptions& o) {
  std::vector<std::string> out;
  if (!o.metrics.empty()) return o.metrics;
  const std::vector<std::string> wanted = o.wide ? c.columns : DefaultColumns(kind);
  for (const auto& col : wanted) {
    // A metric that applies to no row is left out, not shown as 0 or a column of dashes.
    bool any = false;
    for (const auto& r : c.rows)
      if (const MetricStat* s = Stat(r, col); s != nullptr && s->n > 0) any = true;
    if (any) out.push_back(col);
  }
  return out;
}

// Seed 000 Figs. 8-9 as text: per spec name (fig8, fig9), mean position against duty, one column per value of
// the other sweep axes. Empty when the rows are not such a sweep.
std::string StaticMapText(const Comparison& c, const std::string& prefix) {
  struct Point {
    RunKey key;
    double pct;
  };
  std::vector<std::string> groups;
  std::map<std::string, std::vector<Point>> by_group;
  for (const auto& r : c.rows) {
    const MetricStat* s = Stat(r, "mean_position_pct");
    const RunKey& key = r.key;
    if (key.sweep.empty()) return "";
    if (!by_group.count(key.name)) groups.push_back(key.name);
    by_group[key.name].push_back({key, s != nullptr && s->n > 0 ? s->mean : kNaN});
  }
  std::ostringstream os;
  for (const auto& g : groups) {
    const auto& pts = by_group[g];
    // x: the duty axis (else the last); the others, joined, name the curves.
    size_t xi = pts[0].key.sweep.size() - 1;
    for (size_t k = 0; k < pts[0].key.sweep.size(); ++k)
      if (Leaf(pts[0].key.sweep[k].field) == "duty") xi = k;
    std::vector<double> xs;
    std::vector<std::string> curves;
    std::map<std::string, std::map<double, double>> cell;
    std::map<std::string, double> axis_max;
    for (const auto& p : pts)
      for (const auto& sc : p.key.sweep)
        axis_max[sc.field] = std::max(axis_max[sc.field], std::abs(sc.value));
    std::string curve_axes;
    for (const auto& p : pts) {
      if (p.key.sweep.size() != pts[0].key.sweep.size()) return "";
      const double x = p.key.sweep[xi].value;
      if (std::find(xs.begin(), xs.end(), x) == xs.end()) xs.push_back(x);
      std::string curve;
      std::string axes;
      for (size_t k = 0; k < p.key.sweep.size(); ++k) {
        if (k == xi) continue;
        const auto& sc = p.key.sweep[k];
        curve += (curve.empty() ? "" : ", ") + FormatSweepValue(sc.field, sc.value, axis_max[sc.field]);
        axes += (axes.empty() ? "" : ", ") + ViewOf(Leaf(sc.field), ExperimentKind::kGeneric).label;
      }
      curve_axes = axes;
      if (std::find(curves.begin(), curves.end(), curve) == curves.end()) curves.push_back(curve);
      cell[curve][x] = p.pct;
    }
    std::sort(xs.begin(), xs.end());
    const std::string x_field = pts[0].key.sweep[xi].field;
    os << g.substr(std::min(g.size(), prefix.size())) << ": mean position [% of stroke] against "
       << Leaf(x_field) << (curve_axes.empty() ? "" : ", one column per " + curve_axes)
       << " (seed 000 Figs. 8-9)\n";
    std::vector<TextColumn> cols;
    cols.push_back(SweepColumn(x_field, xs));
    for (const auto& cv : curves) {
      TextColumn col;
      col.header = cv.empty() ? "mean x [%]" : cv;
      for (double x : xs) {
        auto it = cell[cv].find(x);
        col.cells.push_back(it == cell[cv].end() || std::isnan(it->second) ? "-" : fmt::format("{:.1f}", it->second));
      }
      cols.push_back(col);
    }
    os << Render(cols, xs.size()) << "\n";
  }
  return os.str();
}

std::string Ordered(const std::string& kind_metric) {
  return kind_metric == "driver_loss_W" ? "driver loss" : kind_metric == "effort_u_l2" ? "||u||2" : kind_metric;
}

}  // namespace

HeadlineMetric RankMetricOf(const std::string& controller) {
  const MetricView v = ViewOf("rmse", KindOf({controller}));
  return {"rmse", v.label, v.unit};
}

HeadlineMetric EffortMetricOf(const std::string& controller) {
  const ExperimentKind kind = KindOf({controller});
  const std::string metric = EffortOf(kind);
  const MetricView v = ViewOf(metric, kind);
  return {metric, v.label, v.unit};
}

ExperimentKind KindOf(const std::vector<std::string>& controllers) {
  static const std::set<std::string> current = {"hysteresis_current", "pi_current", "predictive_current",
                                                "fuzzy_current", "peak_and_hold"};
  static const std::set<std::string> position = {"cascade_pi_position", "sliding_mode_position"};
  std::set<ExperimentKind> kinds;
  for (const auto& c : controllers) {
    if (current.count(c)) {
      kinds.insert(ExperimentKind::kCurrentLaws);
    } else if (position.count(c)) {
      kinds.insert(ExperimentKind::kPositionLaws);
    } else if (c == "dither_pwm") {
      kinds.insert(ExperimentKind::kDither);
    } else if (c == "open_loop_pwm") {
      kinds.insert(ExperimentKind::kOpenLoop);
    } else {
      kinds.insert(ExperimentKind::kGeneric);
    }
  }
  return kinds.size() == 1 ? *kinds.begin() : ExperimentKind::kGeneric;
}

const char* KindName(ExperimentKind kind) {
  switch (kind) {
    case ExperimentKind::kCurrentLaws: return "current_laws";
    case ExperimentKind::kPositionLaws: return "position_laws";
    case ExperimentKind::kDither: return "dither";
    case ExperimentKind::kOpenLoop: return "open_loop";
    case ExperimentKind::kGeneric: break;
  }
  return "generic";
}

std::string SiUnit(const std::string& metric, const std::string& controller) {
  const MetricView v = ViewOf(metric, KindOf({controller}));
  if (v.unit == "%" && v.factor == 100) return "1";  // a ratio shown in %
  if (v.unit.empty()) return "1";
  return v.unit;
}

std::string MetricColumnName(const std::string& metric, const std::string& controller) {
  const std::string unit = SiUnit(metric, controller);
  if (unit.empty() || unit == "1" || unit == "%") return metric;
  for (const char* suffix : {"_A", "_V", "_W", "_J", "_Hz", "_s", "_m", "_pct", "_kg_per_s", "_Pa", "_N"}) {
    const std::string x = suffix;
    if (metric.size() > x.size() && metric.compare(metric.size() - x.size(), x.size(), x) == 0) return metric;
  }
  std::string slug;
  if (unit.size() > 6 && unit.compare(unit.size() - 6, 6, " s^0.5") == 0) {
    slug = unit.substr(0, unit.size() - 6) + "_sqrt_s";
  } else {
    for (char ch : unit) slug += ch == ' ' || ch == '/' ? '_' : ch;
  }
  return metric + "_" + slug;
}

Comparison Compare(const std::vector<RunRecord>& runs) {
  Comparison c;
  std::vector<std::string> controllers;
  for (const auto& r : runs) controllers.push_back(r.controller);
  const ExperimentKind kind = KindOf(controllers);
  c.effort_metric = EffortOf(kind);
  // Every metric some run has: MetricList's order first (stable between calls and machines), then the rest
  // by name.
  std::set<std::string> present;
  for (const auto& r : runs)
    for (const auto& [name, value] : r.metrics) present.insert(name);
  for (const auto& [name, value] : MetricList(Metrics{}))
    if (present.erase(name)) c.columns.push_back(name);
  c.columns.insert(c.columns.end(), present.begin(), present.end());
  // Group by the case (the key without its repeat: repeats of one configuration share it), in first-seen order.
  std::vector<CompareRow> rows;
  std::map<std::string, std::vector<const RunRecord*>> groups;
  for (const auto& r : runs) {
    RunKey case_key = r.key;
    case_key.repeat = -1;
    const std::string name = case_key.CaseName();
    if (groups.find(name) == groups.end()) {
      CompareRow row;
      row.key = std::move(case_key);
      row.name = name;
      row.controller = r.controller;
      rows.push_back(row);
    }
    groups[name].push_back(&r);
  }
  for (auto& row : rows) {
    const auto& members = groups[row.name];
    row.runs = static_cast<int>(members.size());
    for (const auto* r : members)
      if (r->run_id != 0) row.run_ids.push_back(r->run_id);
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
    for (const char* col : {"rmse", "effort_l2"}) row.metrics.try_emplace(col);  // older callers read these
    row.metrics.try_emplace(c.effort_metric);
  }
  // Sort by mean RMSE (missing last, first-seen order kept), then rank: a row only gets a new rank when its
  // RMSE is worse than the previous rank's by more than their combined spread.
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

std::string CheckTableOptions(const Comparison& c, const TableOptions& options) {
  std::string unknown;
  for (const auto& m : options.metrics)
    if (std::find(c.columns.begin(), c.columns.end(), m) == c.columns.end()) unknown += (unknown.empty() ? "" : ", ") + m;
  if (unknown.empty()) return "";
  std::string known;
  for (const auto& m : c.columns) known += (known.empty() ? "" : ",") + m;
  return "--metrics: no metric " + unknown + " in these runs (known: " + known + ")";
}

namespace {

// The long table's columns (rank, case, law, n, sweep axes, metrics, Pareto) and its footnotes.
std::vector<TextColumn> LongColumns(const Comparison& c, const TableOptions& options, ExperimentKind kind,
                                    const std::string& prefix, std::vector<std::string>* notes) {
  std::vector<RunKey> keys;
  for (const auto& r : c.rows) keys.push_back(r.key);
  const bool ranked = std::any_of(c.rows.begin(), c.rows.end(), [](const CompareRow& r) { return r.rank > 0; });
  const bool repeats = std::any_of(c.rows.begin(), c.rows.end(), [](const CompareRow& r) { return r.runs > 1; });
  std::vector<TextColumn> cols;
  const size_t n = c.rows.size();
  if (ranked) {
    TextColumn rank{"rank", {}, false};
    for (const auto& r : c.rows) rank.cells.push_back(r.rank > 0 ? std::to_string(r.rank) : "-");
    cols.push_back(rank);
  }
  TextColumn name{"case", {}, true};
  for (size_t i = 0; i < n; ++i) {
    std::string s = keys[i].name.substr(std::min(keys[i].name.size(), prefix.size()));
    if (s.empty()) s = keys[i].name;
    if (c.rows[i].failed > 0) s += " (" + std::to_string(c.rows[i].failed) + " failed)";
    name.cells.push_back(s);
  }
  // One spec without variants: the case column would repeat its name (said once in the title line).
  const bool one_case = n > 1 && std::all_of(name.cells.begin(), name.cells.end(),
                                             [&](const std::string& x) { return x == name.cells[0]; });
  bool swept = false;
  for (const auto& k : keys) swept = swept || !k.sweep.empty();
  if (!(one_case && swept)) cols.push_back(name);
  // The law, unless every case is named after it ("pi" for pi_current).
  TextColumn law{"law", {}, true};
  bool named_after_law = true;
  for (size_t i = 0; i < n; ++i) {
    const std::string& ctl = c.rows[i].controller;
    law.cells.push_back(LawLabel(ctl));
    named_after_law = named_after_law && !ctl.empty() && name.cells[i].rfind(ctl.substr(0, ctl.find('_')), 0) == 0;
  }
  const bool one_law = std::all_of(c.rows.begin(), c.rows.end(),
                                   [&](const CompareRow& r) { return r.controller == c.rows[0].controller; });
  if (!named_after_law && !(one_case && swept) && !(one_law && n > 1)) cols.push_back(law);
  if (repeats) {
    TextColumn runs{"n", {}, false};
    for (const auto& r : c.rows) runs.cells.push_back(std::to_string(r.runs));
    cols.push_back(runs);
  }
  // Sweep coordinates, one column per axis.
  std::vector<std::string> axes;
  for (const auto& k : keys)
    for (const auto& sc : k.sweep)
      if (std::find(axes.begin(), axes.end(), sc.field) == axes.end()) axes.push_back(sc.field);
  for (const auto& axis : axes) {
    std::vector<double> v;
    for (const auto& k : keys) {
      double x = kNaN;
      for (const auto& sc : k.sweep)
        if (sc.field == axis) x = sc.value;
      v.push_back(x);
    }
    cols.push_back(SweepColumn(axis, v));
  }
  for (const auto& col : ShownColumns(c, kind, options)) {
    std::vector<MetricStat> stats;
    for (const auto& r : c.rows) {
      const MetricStat* s = Stat(r, col);
      stats.push_back(s != nullptr ? *s : MetricStat{});
    }
    const MetricView v = ViewOf(col, kind);
    cols.push_back(NumericColumn(v.label, v, stats));
    // Seed 003 Table I beside what we planned and achieved.
    if (kind == ExperimentKind::kDither && (col == "pwm_frequency_Hz" || col == "pwm_duty" || col == "ripple_pp_A")) {
      std::vector<MetricStat> paper;
      for (size_t i = 0; i < n; ++i) {
        const TableIRow* t = TableIFor(keys[i], c.rows[i]);
        const double x = t == nullptr                 ? kNaN
                         : col == "pwm_frequency_Hz" ? t->f_Hz
                         : col == "pwm_duty"         ? t->duty
                                                     : t->i_amp_A;
        paper.push_back(std::isnan(x) ? MetricStat{} : MetricStat{x, 0, 1});
      }
      MetricView pv = v;
      pv.label = col == "pwm_frequency_Hz" ? "Table I f" : col == "pwm_duty" ? "Table I D" : "Table I I_amp";
      if (col == "pwm_frequency_Hz") cols.back().header = "f plan [Hz]";
      if (col == "pwm_duty") cols.back().header = "D plan [%]";
      cols.push_back(NumericColumn(pv.label, pv, paper));
    }
  }
  const bool front = std::any_of(c.rows.begin(), c.rows.end(), [](const CompareRow& r) { return r.pareto; });
  if (front) {
    TextColumn p{"Pareto", {}, true};
    for (const auto& r : c.rows) p.cells.push_back(r.pareto ? "*" : "");
    cols.push_back(p);
  }
  if (ranked) {
    std::string note = "rank by RMSE (rows within the repeat spread share a rank)";
    if (front) note += "; * = Pareto-optimal in (RMSE, " + Ordered(c.effort_metric) + ")";
    notes->push_back(note);
  }
  if (kind == ExperimentKind::kDither)
    notes->push_back("I_avg = (max i + min i)/2 and I_amp = max i - min i over the metric window, as seed 003 eqs. "
                     "(10)-(11)");
  return cols;
}

ExperimentKind KindOfRows(const Comparison& c) {
  std::vector<std::string> controllers;
  for (const auto& r : c.rows) controllers.push_back(r.controller);
  return KindOf(controllers);
}

std::string PrefixOfRows(const Comparison& c) {
  std::vector<std::string> names;
  for (const auto& r : c.rows) names.push_back(r.key.name);
  return CommonPrefix(names);
}

}  // namespace

std::string ComparisonTable(const Comparison& c, const TableOptions& options) {
  const ExperimentKind kind = KindOfRows(c);
  const std::string prefix = PrefixOfRows(c);
  std::ostringstream os;
  std::string title = prefix.empty() ? "" : prefix.substr(0, prefix.size() - 1);
  if (title.empty() && !c.rows.empty()) {
    title = c.rows[0].key.name;  // one spec's sweep: its name, said once
    for (const auto& r : c.rows)
      if (r.key.name != title) title.clear();
  }
  if (!title.empty()) os << title << ": ";
  os << c.rows.size() << (c.rows.size() == 1 ? " case" : " cases") << " ("
     << (kind == ExperimentKind::kCurrentLaws    ? "current laws, seed 001"
         : kind == ExperimentKind::kPositionLaws ? "position laws, seed 002"
         : kind == ExperimentKind::kDither       ? "dither PWM, seed 003 Table I"
         : kind == ExperimentKind::kOpenLoop     ? "open-loop PWM"
                                                 : "mixed laws")
     << ")\n";
  // Static map sweeps: the paper's form; the long table only when asked for (--wide or --metrics).
  if (kind == ExperimentKind::kOpenLoop && options.metrics.empty() && !options.wide) {
    const std::string map = StaticMapText(c, prefix);
    if (!map.empty()) return os.str() + map + "--wide or --metrics a,b: one row per run; --csv: every value\n";
  }
  std::vector<std::string> notes;
  const auto cols = LongColumns(c, options, kind, prefix, &notes);
  os << Render(cols, c.rows.size());
  for (const auto& n : notes) os << n << "\n";
  if (options.metrics.empty() && !options.wide)
    os << "--wide: every metric; --metrics a,b: pick; --json/--csv: full names, SI units\n";
  return os.str();
}

TableGrid ComparisonGrid(const Comparison& c, const TableOptions& options) {
  std::vector<std::string> notes;
  const auto cols = LongColumns(c, options, KindOfRows(c), PrefixOfRows(c), &notes);
  TableGrid g;
  for (const auto& col : cols) {
    g.headers.push_back(col.header);
    g.left.push_back(col.left);
  }
  for (size_t i = 0; i < c.rows.size(); ++i) {
    std::vector<std::string> row;
    for (const auto& col : cols) row.push_back(col.cells[i]);
    g.rows.push_back(std::move(row));
  }
  return g;
}

MetricDisplay DisplayOf(const Comparison& c, const std::string& metric) {
  const MetricView v = ViewOf(metric, KindOfRows(c));
  double max_abs = 0;
  for (const auto& r : c.rows)
    if (const MetricStat* s = Stat(r, metric); s != nullptr && s->n > 0) max_abs = std::max(max_abs, std::abs(s->mean * v.factor));
  const UnitChoice p = Shown(v, max_abs);
  const std::string unit = v.unit.empty() ? "" : p.unit;
  return {unit.empty() ? v.label : v.label + " [" + unit + "]", v.factor * p.scale};
}

ColumnDisplay MetricColumnDisplay(const Comparison& c, const std::string& metric) {
  const MetricView v = ViewOf(metric, KindOfRows(c));
  std::vector<MetricStat> stats;
  for (const auto& r : c.rows)
    if (const MetricStat* s = Stat(r, metric); s != nullptr) stats.push_back(*s);
  return ChooseDisplay(v.label, v, stats);
}

ColumnDisplay SweepColumnDisplay(const std::string& field, const std::vector<double>& values) {
  const MetricView v = SweepView(field);
  return ChooseDisplay(v.label, v, SweepStats(values));
}

std::vector<std::string> DefaultMetricColumns(const Comparison& c) {
  return ShownColumns(c, KindOfRows(c), TableOptions{});
}

std::vector<SiPrefix> SiPrefixes() {
  std::vector<SiPrefix> out;
  for (const auto& p : UnitPrefixes()) out.push_back({p.symbol, p.scale});
  return out;
}

std::string LawName(const std::string& controller) { return LawLabel(controller); }

std::string ComparisonCsv(const Comparison& c) {
  std::vector<RunKey> keys;
  std::vector<std::string> axes;
  for (const auto& r : c.rows) {
    keys.push_back(r.key);
    for (const auto& sc : keys.back().sweep)
      if (std::find(axes.begin(), axes.end(), sc.field) == axes.end()) axes.push_back(sc.field);
  }
  std::ostringstream os;
  os << "rank,name,controller,runs,failed,pareto";
  for (const auto& a : axes) os << "," << CsvQuoted(a);
  // Unit-suffixed headers (rmse_A, iae_A_s): the values are SI, the header says which.
  const std::string law = c.rows.empty() ? "" : c.rows.front().controller;
  for (const auto& col : c.columns) {
    const std::string name = MetricColumnName(col, law);
    os << "," << name << "," << name << "_spread";
  }
  os << "\n";
  os.precision(10);
  for (size_t i = 0; i < c.rows.size(); ++i) {
    const CompareRow& r = c.rows[i];
    os << r.rank << "," << CsvQuoted(r.name) << "," << r.controller << "," << r.runs << "," << r.failed << ","
       << (r.pareto ? 1 : 0);
    for (const auto& a : axes) {
      os << ",";
      for (const auto& sc : keys[i].sweep)
        if (sc.field == a) os << sc.value;
    }
    for (const auto& col : c.columns) {
      const MetricStat* s = Stat(r, col);
      if (s == nullptr || s->n == 0) {
        os << ",,";
      } else {
        os << "," << s->mean << "," << s->spread;
      }
    }
    os << "\n";
  }
  return os.str();
}

std::string ComparisonJson(const Comparison& c) {
  using Json = nlohmann::ordered_json;
  std::vector<std::string> controllers;
  for (const auto& r : c.rows) controllers.push_back(r.controller);
  Json rows = Json::array();
  for (const auto& r : c.rows) {
    Json m = Json::object();
    for (const auto& col : c.columns) {
      const MetricStat* s = Stat(r, col);
      m[col] = s == nullptr || s->n == 0 ? Json(nullptr) : Json{{"mean", s->mean}, {"spread", s->spread}, {"n", s->n}};
    }
    Json sweep = Json::object();
    Json key_sweep = Json::array();
    for (const auto& sc : r.key.sweep) {
      sweep[sc.field] = sc.value;
      key_sweep.push_back({{"field", sc.field}, {"value", sc.value}});
    }
    rows.push_back({{"rank", r.rank},
                    {"name", r.name},
                    {"key", {{"name", r.key.name}, {"sweep", key_sweep}}},
                    {"run_ids", r.run_ids},
                    {"controller", r.controller},
                    {"runs", r.runs},
                    {"failed", r.failed},
                    {"pareto", r.pareto},
                    {"sweep", sweep},
                    {"metrics", m}});
  }
  return Json{{"kind", KindName(KindOf(controllers))},
              {"rank_metric", c.rank_metric},
              {"effort_metric", c.effort_metric},
              {"columns", c.columns},
              {"rows", rows}}
             .dump(2) +
         "\n";
}

}  // namespace vb::experiment
