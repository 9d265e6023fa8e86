#include "report/report.h"
#include "common/decimate.h"
#include "common/format.h"

#include <fmt/format.h>
#include <fmt/printf.h>

#include <algorithm>
#include <ctime>
#include <cmath>
#include <cstdio>
#include <limits>

namespace vb::report {
namespace {

Json Num(double v) { return std::isfinite(v) ? Json(v) : Json(nullptr); }

// f is a printf-style spec for one double (callers choose the precision of each table column).
std::string Fmt(double v, const char* f = "%.6g") {
  if (!std::isfinite(v)) return "n/a";
  return fmt::sprintf(f, v);
}

}  // namespace

Json TraceSection(const std::vector<TraceData>& traces, std::size_t max_points, std::size_t open) {
  Json runs = Json::array();
  for (const auto& t : traces) {
    std::map<std::string, std::vector<double>> used;
    std::size_t n = 0;
    for (const char* name : {"gate", "i_A", "ref", "x_m", "v_coil_V"}) {
      auto it = t.channels.find(name);
      if (it == t.channels.end() || it->second.empty()) continue;
      used[name] = it->second;
      n = n == 0 ? it->second.size() : std::min(n, it->second.size());
    }
    if (n == 0) continue;
    // The server's GetTrace decimator (common/decimate.h): every channel's peaks survive.
    std::vector<const std::vector<double>*> cols;
    for (auto& [name, v] : used) {
      v.resize(n);
      cols.push_back(&v);
    }
    const MinMaxDecimator::Rows rows = DecimateColumns(cols, t.t0_s, t.sample_period_s, static_cast<std::int64_t>(max_points));
    Json r = {{"label", t.label}, {"controlled", t.controlled}, {"samples", n}};
    r["t"] = rows.t_s;
    std::size_t j = 0;
    for (const auto& [name, v] : used) {
      Json a = Json::array();
      for (double x : rows.values[j]) a.push_back(Num(x));
      r[name] = a;
      ++j;
    }
    runs.push_back(r);
  }
  return {{"kind", "traces"}, {"title", "Traces (drag to zoom, double-click to reset)"}, {"runs", runs}, {"open", open}};
}

Json ComparisonSections(const experiment::Comparison& c, const std::string& title) {
  Json out = Json::array();
  // The terminal table's columns, headers and units (experiment::ComparisonGrid): one definition of both.
  const experiment::TableGrid g = experiment::ComparisonGrid(c);
  Json rows = Json::array();
  for (const auto& r : g.rows) rows.push_back(r);
  Json left = Json::array();
  for (bool l : g.left) left.push_back(l);
  out.push_back({{"kind", "table"}, {"title", title}, {"columns", g.headers}, {"left", left}, {"rows", rows}});
  const experiment::MetricDisplay ex = experiment::DisplayOf(c, c.rank_metric);
  const experiment::MetricDisplay fx = experiment::DisplayOf(c, c.effort_metric);
  Json points = Json::array();
  for (const auto& r : c.rows) {
    auto e = r.metrics.find(c.rank_metric), f = r.metrics.find(c.effort_metric);
    if (e == r.metrics.end() || f == r.metrics.end() || e->second.n == 0 || f->second.n == 0) continue;
    const std::string& label = r.key.name;
    points.push_back({{"label", label.substr(label.rfind('/') == std::string::npos ? 0 : label.rfind('/') + 1)},
                      {"x", f->second.mean * fx.scale},
                      {"y", e->second.mean * ex.scale},
                      {"front", r.pareto},
                      {"controller", r.controller},  // the law's colour on the page
                      {"x_err", f->second.spread * fx.scale},
                      {"y_err", e->second.spread * ex.scale}});
  }
  if (points.size() > 1)
    out.push_back({{"kind", "scatter"},
                   {"title", "Tracking error against effort (Pareto front joined; lower left is better)"},
                   {"x_label", fx.header},
                   {"y_label", ex.header},
                   {"points", points}});
  return out;
}

Json MetricsSection(const std::string& title, const std::vector<std::pair<std::string, double>>& metrics) {
  Json rows = Json::array();
  for (const auto& [name, v] : metrics)
    if (std::isfinite(v)) rows.push_back(Json::array({name, Fmt(v, "%.9g")}));
  return {{"kind", "table"}, {"title", title}, {"columns", Json::array({"metric", "value"})}, {"rows", rows}};
}

Json StaticMapSection(const std::vector<MapPoint>& points, const std::string& metric_label) {
  // Per spec name (fig8, fig9): x is the duty axis (else the last), one curve per value of the other axes.
  std::vector<std::string> names;
  std::map<std::string, std::map<std::string, std::map<double, std::vector<double>>>> by;  // name -> curve -> x -> ys
  std::map<std::string, std::vector<std::string>> curve_order;
  std::map<std::string, std::string> x_field;
  auto leaf = [](const std::string& f) { return f.substr(f.rfind('.') == std::string::npos ? 0 : f.rfind('.') + 1); };
  for (const auto& p : points) {
    if (!std::isfinite(p.value) || p.key.sweep.empty()) continue;
    size_t xi = p.key.sweep.size() - 1;
    for (size_t k = 0; k < p.key.sweep.size(); ++k)
      if (leaf(p.key.sweep[k].field) == "duty") xi = k;
    std::string curve;
    for (size_t k = 0; k < p.key.sweep.size(); ++k) {
      if (k == xi) continue;
      const auto& sc = p.key.sweep[k];
      const std::string l = leaf(sc.field);
      // Seed 000 states pressures in bar, frequencies in Hz.
      curve += (curve.empty() ? "" : ", ") +
               (l == "supply_pressure_Pa" ? fmt::format("{:g} bar", sc.value / 1e5)
                : l.size() > 3 && l.compare(l.size() - 3, 3, "_Hz") == 0 ? fmt::format("{:g} Hz", sc.value)
                                                                          : fmt::format("{} = {:g}", l, sc.value));
    }
    if (!by.count(p.key.name)) names.push_back(p.key.name);
    if (!by[p.key.name].count(curve)) curve_order[p.key.name].push_back(curve);
    x_field[p.key.name] = p.key.sweep[xi].field;
    by[p.key.name][curve][p.key.sweep[xi].value].push_back(p.value);
  }
  Json out = Json::array();
  for (const auto& name : names) {
    std::size_t total = 0;
    for (const auto& [c, xs] : by[name]) total += xs.size();
    if (total < 3) continue;
    const bool duty = leaf(x_field[name]) == "duty";
    Json series = Json::array();
    for (const auto& curve : curve_order[name]) {
      Json xs = Json::array(), ys = Json::array();
      for (const auto& [x, vs] : by[name][curve]) {
        double sum = 0;
        for (double v : vs) sum += v;
        xs.push_back(duty ? 100.0 * x : x);
        ys.push_back(sum / vs.size());
      }
      series.push_back({{"name", curve.empty() ? metric_label : curve}, {"x", xs}, {"y", ys}});
    }
    out.push_back({{"kind", "lines"},
                   {"title", "Static map, " + name + ": " + metric_label + " against " +
                                 (duty ? std::string("PWM duty") : leaf(x_field[name])) + " (seed 000 Figs. 8-9)"},
                   {"x_label", duty ? std::string("duty [%]") : leaf(x_field[name])},
                   {"y_label", metric_label},
                   {"markers", true},
                   {"series", series}});
  }
  return out;
}

namespace {

std::string Utc(double unix_s) { return unix_s > 0 ? FormatUtc(unix_s) : ""; }

Json ParseSpec(const std::string& spec_json) {
  if (spec_json.empty()) return nullptr;
  try {
    return Json::parse(spec_json);
  } catch (const Json::exception&) {
    return nullptr;
  }
}

double SpecNumber(const Json& spec, std::initializer_list<const char*> path, double fallback) {
  const Json* j = &spec;
  for (const char* k : path) {
    if (!j->is_object() || !j->contains(k)) return fallback;
    j = &(*j)[k];
  }
  return j->is_number() ? j->get<double>() : fallback;
}

// [start, end] of the metric window (docs/spec.md: default the whole run).
std::pair<double, double> MetricWindow(const Json& spec) {
  const double duration = SpecNumber(spec, {"duration_s"}, NAN);
  return {SpecNumber(spec, {"metric_window", "start_s"}, 0.0), SpecNumber(spec, {"metric_window", "end_s"}, duration)};
}

std::string Controlled(const std::string& controller) {
  auto ends = [&](const char* suf) {
    const std::string s(suf);
    return controller.size() >= s.size() && controller.compare(controller.size() - s.size(), s.size(), s) == 0;
  };
  if (ends("_current") || controller == "peak_and_hold") return "current";
  if (ends("_position")) return "position";
  return "";
}

// The SI prefix for a channel whose largest magnitude is max_abs: (symbol, scale).
std::pair<std::string, double> PrefixFor(double max_abs) {
  if (max_abs >= 1) return {"", 1};
  if (max_abs >= 1e-3) return {"m", 1e3};
  if (max_abs >= 1e-6) return {"µ", 1e6};
  return {"n", 1e9};
}

}  // namespace

Json MetaSection(const std::string& where, const std::vector<RunInfo>& runs) {
  Json rows = Json::array();
  auto add = [&](const std::string& k, const std::string& v) {
    if (!v.empty()) rows.push_back(Json::array({k, v}));
  };
  add("page made", Utc(static_cast<double>(std::time(nullptr))));
  add("runs from", where);
  double first = 0, last = 0;
  int done = 0;
  for (const auto& r : runs) {
    if (r.started_unix_s > 0 && (first == 0 || r.started_unix_s < first)) first = r.started_unix_s;
    last = std::max(last, r.finished_unix_s);
    done += r.status == RunStatus::kDone;
  }
  add("runs", std::to_string(runs.size()) + " (" + std::to_string(done) + " done)");
  if (first > 0) add("ran", Utc(first) + " to " + Utc(last));
  const Json spec = runs.empty() ? Json(nullptr) : ParseSpec(runs.front().spec_json);
  if (spec.is_object()) {
    auto str = [&](std::initializer_list<const char*> path) {
      const Json* j = &spec;
      for (const char* k : path) {
        if (!j->is_object() || !j->contains(k)) return std::string();
        j = &(*j)[k];
      }
      return j->is_string() ? j->get<std::string>() : j->dump();
    };
    add("description", str({"description"}));
    add("bench", str({"bench", "model", "preset"}) + (str({"bench", "driver", "kind"}).empty() ? "" : ", driver " + str({"bench", "driver", "kind"})));
    std::string cond;
    if (spec.contains("conditions") && spec["conditions"].is_object())
      for (const auto& [k, v] : spec["conditions"].items())
        if (v.is_number()) cond += (cond.empty() ? "" : ", ") + k + " = " + fmt::format("{:g}", v.get<double>());
    add("conditions", cond);
    const auto [w0, w1] = MetricWindow(spec);
    add("duration", fmt::format("{:g} s; metric window {:g}-{:g} s", SpecNumber(spec, {"duration_s"}, NAN), w0, w1));
  }
  Json specs = Json::array();
  for (const auto& r : runs)
    if (!r.spec_json.empty()) {
      const Json j = ParseSpec(r.spec_json);
      specs.push_back({{"label", "run " + std::to_string(r.id) + ": " + r.key.DisplayName()},
                       {"text", j.is_null() ? r.spec_json : j.dump(2)}});
    }
  return {{"kind", "meta"}, {"title", "Runs, conditions and specs"}, {"rows", rows}, {"specs", specs}};
}

Json OverlaySection(const std::vector<RunInfo>& runs, std::size_t max_points) {
  std::string controlled;
  for (const auto& r : runs) {
    const std::string c = Controlled(r.controller);
    if (c.empty() || (!controlled.empty() && c != controlled)) return nullptr;
    controlled = c;
  }
  const std::string ych = controlled == "current" ? "i_A" : "x_m";
  // Units: the largest magnitude of the controlled variable and of the error over the window.
  double y_max = 0, e_max = 0;
  struct Prepared {
    const RunInfo* run;
    const std::vector<double>* y;
    const std::vector<double>* ref;
    double w0, w1;
  };
  std::vector<Prepared> ready;
  for (const auto& r : runs) {
    auto y = r.trace.channels.find(ych), ref = r.trace.channels.find("ref");
    if (y == r.trace.channels.end() || ref == r.trace.channels.end() || y->second.empty()) continue;
    auto [w0, w1] = MetricWindow(ParseSpec(r.spec_json));
    const double dt = r.trace.sample_period_s;
    const std::size_t n = std::min(y->second.size(), ref->second.size());
    if (!std::isfinite(w1)) w1 = r.trace.t0_s + dt * static_cast<double>(n);
    for (std::size_t k = 0; k < n; ++k) {
      const double t = r.trace.t0_s + dt * static_cast<double>(k);
      if (std::isfinite(y->second[k])) y_max = std::max(y_max, std::abs(y->second[k]));
      if (t >= w0 && t <= w1 && std::isfinite(ref->second[k]))
        e_max = std::max(e_max, std::abs(y->second[k] - ref->second[k]));
    }
    ready.push_back({&r, &y->second, &ref->second, w0, w1});
  }
  if (ready.size() < 1) return nullptr;
  const auto [yp, ys] = PrefixFor(y_max);
  const auto [ep, es] = PrefixFor(e_max);
  const std::string base = controlled == "current" ? "A" : "m";
  Json series = Json::array();
  double w0_all = INFINITY, w1_all = -INFINITY;
  for (const auto& p : ready) {
    const RunInfo& r = *p.run;
    const double dt = r.trace.sample_period_s;
    const std::size_t n = std::min(p.y->size(), p.ref->size());
    std::vector<double> y_n(p.y->begin(), p.y->begin() + static_cast<std::ptrdiff_t>(n));
    std::vector<double> ref_n(p.ref->begin(), p.ref->begin() + static_cast<std::ptrdiff_t>(n));
    const MinMaxDecimator::Rows yr = DecimateColumns({&y_n, &ref_n}, r.trace.t0_s, dt, static_cast<std::int64_t>(max_points));
    Json t = yr.t_s, y = Json::array(), ref = Json::array();
    for (std::size_t k = 0; k < yr.t_s.size(); ++k) {
      y.push_back(Num(yr.values[0][k] * ys));
      ref.push_back(Num(yr.values[1][k] * ys));
    }
    // The error over the metric window only: where the metrics are computed.
    std::size_t k0 = 0, k1 = 0;
    while (k0 < n && r.trace.t0_s + dt * k0 < p.w0 - 1e-12) ++k0;
    k1 = k0;
    while (k1 < n && r.trace.t0_s + dt * k1 <= p.w1 + 1e-12) ++k1;
    std::vector<double> err;
    for (std::size_t k = k0; k < k1; ++k) err.push_back((*p.y)[k] - (*p.ref)[k]);
    const MinMaxDecimator::Rows er =
        DecimateColumns({&err}, r.trace.t0_s + dt * static_cast<double>(k0), dt, static_cast<std::int64_t>(max_points));
    Json et = er.t_s, ev = Json::array();
    for (double e : er.values[0]) ev.push_back(Num(e * es));
    const std::string label = r.key.DisplayName();
    series.push_back({{"name", label.substr(label.rfind('/') == std::string::npos ? 0 : label.rfind('/') + 1)},
                      {"controller", r.controller}, {"t", t}, {"y", y}, {"ref", ref}, {"et", et}, {"e", ev}});
    w0_all = std::min(w0_all, p.w0);
    w1_all = std::max(w1_all, p.w1);
  }
  const std::string what = controlled == "current" ? "current" : "position";
  return {{"kind", "overlay"},
          {"title", "The compared laws on shared axes: " + what + " and tracking error (metric window shaded)"},
          {"y_label", what + " [" + yp + base + "]"},
          {"e_label", "error " + what + " - reference [" + ep + base + "]"},
          {"window", Json::array({w0_all, w1_all})},
          {"series", series}};
}

Json BatchSections(const std::string& where, std::int64_t batch, const std::vector<RunInfo>& runs) {
  Json sections = Json::array();
  sections.push_back(MetaSection(where, runs));
  std::vector<experiment::RunRecord> recs;
  std::vector<MapPoint> map;
  for (const auto& r : runs) {
    recs.push_back({r.key, r.id, r.controller, r.status == RunStatus::kDone, r.metrics});
    auto it = r.metrics.find("mean_position_pct");
    if (r.status == RunStatus::kDone && r.controller == "open_loop_pwm" && it != r.metrics.end()) map.push_back({r.key, it->second});
  }
  sections.push_back({{"kind", "note"},
                      {"text", "Batch " + std::to_string(batch) + ": " + std::to_string(runs.size()) +
                                   " runs. Repeats are grouped: mean \u00b1 sample standard deviation. Metric "
                                   "definitions: docs/metrics.md."}});
  const experiment::Comparison c = experiment::Compare(recs);
  // A static map first as the paper's figures, its table (a row per run) after them.
  for (auto& s : StaticMapSection(map, "mean position [% of stroke]")) sections.push_back(s);
  for (auto& s : ComparisonSections(c, "Comparison")) {
    if (s["kind"] == "table" && s["rows"].size() > 20) s["collapsed"] = true;  // opened on demand
    sections.push_back(s);
  }
  Json overlay = OverlaySection(runs);
  if (!overlay.is_null()) sections.push_back(overlay);
  std::vector<TraceData> traces;
  for (const auto& r : runs)
    if (!r.trace.channels.empty()) {
      traces.push_back(r.trace);
      if (traces.back().controlled.empty()) traces.back().controlled = Controlled(r.controller);
    }
  const std::size_t points = traces.size() <= 4 ? 4000 : std::max<std::size_t>(600, 16000 / traces.size());
  sections.push_back(TraceSection(traces, points, 2));
  return sections;
}

Json RunSections(const std::string& where, const RunInfo& run) {
  Json sections = Json::array();
  sections.push_back(MetaSection(where, {run}));
  std::vector<TraceData> traces;
  if (!run.trace.channels.empty()) {
    traces.push_back(run.trace);
    if (traces.back().controlled.empty()) traces.back().controlled = Controlled(run.controller);
  }
  sections.push_back(TraceSection(traces, 4000, 1));
  std::vector<std::pair<std::string, double>> m(run.metrics.begin(), run.metrics.end());
  sections.push_back(MetricsSection("Metrics (SI units, names as in --json; docs/metrics.md)", m));
  return sections;
}

Json RegressionSections(const Json& r) {
  Json out = Json::array();
  auto str = [](const Json& j, const char* k) {
    return j.is_object() && j.contains(k) && j[k].is_string() ? j[k].get<std::string>() : std::string();
  };
  auto num = [](const Json& j, const char* k) {
    return j.is_object() && j.contains(k) && j[k].is_number() ? j[k].get<double>()
                                                              : std::numeric_limits<double>::quiet_NaN();
  };
  std::string head = "Suite " + str(r, "suite");
  if (r.contains("baseline") && r["baseline"].is_object())
    head += " vs baseline " + str(r["baseline"], "name") + " v" + std::to_string(r["baseline"].value("version", 0));
  if (!str(r, "night").empty()) head += ", night " + str(r, "night");
  if (r.contains("batch_id") && r["batch_id"].is_number() && r["batch_id"].get<double>() > 0)
    head += ", batch " + r["batch_id"].dump() + " (benchctl report --batch " + r["batch_id"].dump() + ": its specs and conditions)";
  if (const std::string when = Utc(num(r, "created_unix_s")); !when.empty()) head += ", run " + when;
  head += ": " + str(r, "verdict");
  if (r.contains("counts") && r["counts"].is_object()) {
    const Json& c = r["counts"];
    head += " (" + std::to_string(c.value("regressed", 0)) + " regressed, " + std::to_string(c.value("improved", 0)) +
            " improved, " + std::to_string(c.value("unchanged", 0)) + " unchanged, " + std::to_string(c.value("new", 0)) +
            " new)";
  }
  out.push_back({{"kind", "note"}, {"text", head}, {"class", str(r, "verdict") == "passed" ? "good" : "bad"}});
  Json rows = Json::array(), classes = Json::array();
  Json labels = Json::array(), ratios = Json::array(), bar_classes = Json::array();
  if (r.contains("failures") && r["failures"].is_object())
    for (const auto& [c, list] : r["failures"].items())
      if (list.is_array())
        for (const auto& s : list) {
          rows.push_back(Json::array({c, "run", "FAILED", s.is_string() ? s.get<std::string>() : "", "", "", ""}));
          classes.push_back("regressed");
        }
  if (r.contains("findings") && r["findings"].is_array()) {
    for (const auto& f : r["findings"]) {
      const double bm = f.contains("baseline") ? num(f["baseline"], "mean") : NAN;
      const double bs = f.contains("baseline") ? num(f["baseline"], "spread") : NAN;
      const double nm = f.contains("now") ? num(f["now"], "mean") : NAN;
      const double ns = f.contains("now") ? num(f["now"], "spread") : NAN;
      const double d = num(f, "delta"), allowed = num(f, "allowed");
      const std::string verdict = str(f, "verdict");
      rows.push_back(Json::array({str(f, "case"), str(f, "metric"), verdict, Fmt(bm) + " \u00b1 " + Fmt(bs, "%.2g"),
                                  Fmt(nm) + " \u00b1 " + Fmt(ns, "%.2g"),
                                  std::isfinite(d) && std::isfinite(bm) && bm != 0
                                      ? Fmt(d) + " (" + Fmt(100.0 * d / std::fabs(bm), "%+.2f") + " %)"
                                      : Fmt(d),
                                  Fmt(allowed)}));
      classes.push_back(verdict);
      if (std::isfinite(d) && std::isfinite(allowed)) {
        const std::string dir = str(f, "direction");
        const double worse = dir == "higher" ? -d : dir == "both" ? std::fabs(d) : d;
        labels.push_back(str(f, "case") + " " + str(f, "metric"));
        ratios.push_back(allowed > 0 ? worse / allowed : (worse > 0 ? 10.0 : worse < 0 ? -10.0 : 0.0));
        bar_classes.push_back(verdict);
      }
    }
  }
  out.push_back({{"kind", "table"},
                 {"title", "Every metric against the baseline"},
                 {"columns", Json::array({"case", "metric", "verdict", "baseline (mean \u00b1 spread)",
                                          "now (mean \u00b1 spread)", "change", "allowed"})},
                 {"rows", rows},
                 {"row_classes", classes}});
  if (!labels.empty())
    out.push_back({{"kind", "bars"},
                   {"title", "Change in the worse direction / allowance (beyond +1 = regressed, below -1 = improved)"},
                   {"labels", labels},
                   {"values", ratios},
                   {"classes", bar_classes},
                   {"limits", Json::array({-1.0, 1.0})}});
  return out;
}

Json DiagnosisSections(const Json& d) {
  Json out = Json::array();
  if (!d.is_object()) {
    out.push_back({{"kind", "note"}, {"text", "The diagnosis file is not a JSON object: nothing to show."}, {"class", "bad"}});
    return out;
  }
  std::vector<std::string> missing;
  Json summary = Json::array();
  auto add = [&](const std::string& k, const Json& v) {
    if (v.is_string()) summary.push_back(Json::array({k, v.get<std::string>()}));
    else if (v.is_number()) summary.push_back(Json::array({k, Fmt(v.get<double>(), "%.6g")}));
    else if (v.is_boolean()) summary.push_back(Json::array({k, v.get<bool>() ? "yes" : "no"}));
  };
  for (const char* k : {"model", "noise_floor_A"}) {
    if (d.contains(k)) add(k, d[k]);
    else missing.push_back(k);
  }
  if (d.contains("gap") && d["gap"].is_object()) {
    for (const char* k : {"fit_rmse_A", "holdout_rmse_A", "significant"})
      if (d["gap"].contains(k)) add(std::string("gap.") + k, d["gap"][k]);
  } else {
    missing.push_back("gap");
  }
  if (d.contains("verdict")) {
    if (d["verdict"].is_string()) add("verdict", d["verdict"]);
    else add("verdict", Json(d["verdict"].dump()));
  } else {
    missing.push_back("verdict");
  }
  out.push_back({{"kind", "table"}, {"title", "Gap diagnosis"}, {"columns", Json::array({"item", "value"})},
                 {"rows", summary}});
  if (d.contains("where") && d["where"].is_array() && !d["where"].empty()) {
    Json labels = Json::array(), values = Json::array(), rows = Json::array();
    for (const auto& w : d["where"]) {
      if (!w.is_object()) continue;
      const std::string phase = w.value("phase", std::string("?"));
      const double share = w.contains("share") && w["share"].is_number() ? w["share"].get<double>() : NAN;
      const double rmse = w.contains("rmse_A") && w["rmse_A"].is_number() ? w["rmse_A"].get<double>() : NAN;
      if (std::isfinite(share)) {
        labels.push_back(phase);
        values.push_back(share);
      }
      rows.push_back(Json::array({phase, Fmt(share, "%.3f"), Fmt(rmse)}));
    }
    if (!labels.empty())
      out.push_back({{"kind", "bars"}, {"title", "Where the gap lies: share of the squared error per phase"},
                     {"labels", labels}, {"values", values}});
    out.push_back({{"kind", "table"}, {"title", "Per phase"}, {"columns", Json::array({"phase", "share", "rmse_A"})},
                   {"rows", rows}});
  } else {
    missing.push_back("where");
  }
  if (d.contains("ranking") && d["ranking"].is_array() && !d["ranking"].empty()) {
    Json rows = Json::array();
    for (const auto& r : d["ranking"]) {
      if (!r.is_object()) continue;
      auto n = [&](const char* k) { return r.contains(k) && r[k].is_number() ? r[k].get<double>() : NAN; };
      // Fitted values as "name = value +- sigma", short enough to read.
      std::string params;
      if (r.contains("params") && r["params"].is_object()) {
        for (const auto& [k, v] : r["params"].items()) {
          if (!v.is_number()) continue;
          if (!params.empty()) params += ", ";
          params += k + " = " + Fmt(v.get<double>(), "%.4g");
          if (r.contains("uncertainty") && r["uncertainty"].is_object() && r["uncertainty"].contains(k) &&
              r["uncertainty"][k].is_number())
            params += " \u00b1 " + Fmt(r["uncertainty"][k].get<double>(), "%.2g");
        }
      }
      const Json closed = r.contains("closed") ? r["closed"] : Json(nullptr);
      rows.push_back(Json::array({r.value("effect", std::string("?")), Fmt(n("holdout_rmse_before_A")),
                                  Fmt(n("holdout_rmse_after_A")),
                                  closed.is_boolean() ? (closed.get<bool>() ? "yes" : "no")
                                  : closed.is_number() ? Fmt(closed.get<double>(), "%.3f")
                                                       : "",
                                  params}));
    }
    out.push_back({{"kind", "table"},
                   {"title", "Candidate effects, ranked"},
                   {"columns", Json::array({"effect", "holdout rmse before [A]", "after [A]", "closed", "fitted"})},
                   {"rows", rows}});
  } else {
    missing.push_back("ranking");
  }
  if (d.contains("overlays") && d["overlays"].is_array() && !d["overlays"].empty()) {
    for (const auto& o : d["overlays"]) {
      if (!o.is_object() || !o.contains("t_s") || !o["t_s"].is_array()) continue;
      Json series = Json::array();
      for (const char* k : {"measured_A", "nominal_A", "fitted_A"}) {
        if (!o.contains(k) || !o[k].is_array()) continue;
        // Measured wide and solid, the model curves thin and dashed: a fitted curve never hides the measurement.
        const bool measured = std::string(k) == "measured_A";
        series.push_back({{"name", std::string(k).substr(0, std::string(k).size() - 2)}, {"x", o["t_s"]}, {"y", o[k]},
                          {"width", measured ? 3.0 : 1.3}, {"dash", measured ? "" : "6,3"}});
      }
      if (series.empty()) continue;
      const std::string run = o.contains("run") ? (o["run"].is_string() ? o["run"].get<std::string>() : o["run"].dump())
                                                : "?";
      out.push_back({{"kind", "lines"},
                     {"title", "Run " + run + ": measured vs nominal vs fitted current (drag to zoom)"},
                     {"x_label", "t [s]"},
                     {"y_label", "i [A]"},
                     {"zoom", true},
                     {"series", series}});
    }
  } else {
    missing.push_back("overlays");
  }
  if (!missing.empty()) {
    std::string list;
    for (const auto& m : missing) list += (list.empty() ? "" : ", ") + m;
    out.push_back({{"kind", "note"}, {"text", "Not in this diagnosis file: " + list + "."}});
  }
  return out;
}

}  // namespace vb::report
