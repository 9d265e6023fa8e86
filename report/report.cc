#include "report/report.h"

#include <fmt/printf.h>
#include <algorithm>
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

// Indices kept by min/max decimation: per bucket the first sample and the min and max of every channel.
std::vector<std::size_t> DecimationIndices(const std::map<std::string, std::vector<double>>& ch, std::size_t n,
                                           std::size_t max_points) {
  std::vector<std::size_t> keep;
  if (n <= max_points) {
    keep.resize(n);
    for (std::size_t k = 0; k < n; ++k) keep[k] = k;
    return keep;
  }
  const std::size_t per_bucket = std::max<std::size_t>(1, ch.size() * 2 + 1);
  const std::size_t buckets = std::max<std::size_t>(1, max_points / per_bucket);
  const double width = static_cast<double>(n) / buckets;
  for (std::size_t b = 0; b < buckets; ++b) {
    const std::size_t lo = static_cast<std::size_t>(b * width), hi = std::min(n, static_cast<std::size_t>((b + 1) * width));
    if (lo >= hi) continue;
    std::vector<std::size_t> in = {lo};
    for (const auto& [name, v] : ch) {
      if (v.size() < hi) continue;
      auto [mn, mx] = std::minmax_element(v.begin() + lo, v.begin() + hi);
      in.push_back(static_cast<std::size_t>(mn - v.begin()));
      in.push_back(static_cast<std::size_t>(mx - v.begin()));
    }
    std::sort(in.begin(), in.end());
    in.erase(std::unique(in.begin(), in.end()), in.end());
    keep.insert(keep.end(), in.begin(), in.end());
  }
  if (keep.back() != n - 1) keep.push_back(n - 1);
  return keep;
}

}  // namespace

Json TraceSection(const std::vector<TraceData>& traces, std::size_t max_points) {
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
    const auto keep = DecimationIndices(used, n, max_points);
    Json r = {{"label", t.label}, {"controlled", t.controlled}, {"samples", n}};
    Json ts = Json::array();
    for (auto k : keep) ts.push_back(t.t0_s + static_cast<double>(k) * t.sample_period_s);
    r["t"] = ts;
    for (const auto& [name, v] : used) {
      Json a = Json::array();
      for (auto k : keep) a.push_back(Num(v[k]));
      r[name] = a;
    }
    runs.push_back(r);
  }
  return {{"kind", "traces"}, {"title", "Traces (drag to zoom, double-click to reset)"}, {"runs", runs}};
}

Json ComparisonSections(const experiment::Comparison& c, const std::string& title) {
  Json out = Json::array();
  Json cols = Json::array({"rank", "name", "controller", "runs", "failed", "Pareto"});
  for (const auto& col : c.columns) cols.push_back(col);
  Json rows = Json::array();
  Json points = Json::array();
  for (const auto& r : c.rows) {
    Json row = Json::array({r.rank, r.name, r.controller, r.runs, r.failed, r.pareto ? "*" : ""});
    for (const auto& col : c.columns) {
      const auto& s = r.metrics.at(col);
      row.push_back(s.n == 0 ? std::string("") : Fmt(s.mean) + (s.n > 1 ? " \u00b1 " + Fmt(s.spread, "%.2g") : ""));
    }
    rows.push_back(row);
    const auto& e = r.metrics.at(c.rank_metric);
    const auto& f = r.metrics.at(c.effort_metric);
    if (e.n > 0 && f.n > 0)
      points.push_back({{"label", r.name}, {"x", f.mean}, {"y", e.mean}, {"front", r.pareto},
                        {"x_err", f.spread}, {"y_err", e.spread}});
  }
  out.push_back({{"kind", "table"}, {"title", title}, {"columns", cols}, {"rows", rows}});
  if (!points.empty())
    out.push_back({{"kind", "scatter"},
                   {"title", "Controller comparison: " + c.rank_metric + " vs " + c.effort_metric +
                                 " (Pareto front joined; lower-left is better)"},
                   {"x_label", c.effort_metric},
                   {"y_label", c.rank_metric},
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
  std::map<std::string, std::map<double, std::vector<double>>> series;  // series -> x -> values (repeats)
  std::vector<std::string> order;
  std::string axis;
  for (const auto& p : points) {
    if (!std::isfinite(p.value) || p.key.sweep.empty()) continue;
    const std::string& a = p.key.sweep.back().field;
    const double x = p.key.sweep.back().value;
    const std::string s =
        RunKey{p.key.name, {p.key.sweep.begin(), p.key.sweep.end() - 1}, -1}.CaseName();
    if (axis.empty()) axis = a;
    if (a != axis) continue;
    if (!series.count(s)) order.push_back(s);
    series[s][x].push_back(p.value);
  }
  std::size_t total = 0;
  for (const auto& [s, xs] : series) total += xs.size();
  if (total < 3) return nullptr;
  Json out = Json::array();
  for (const auto& s : order) {
    Json xs = Json::array(), ys = Json::array();
    for (const auto& [x, vs] : series[s]) {
      double sum = 0;
      for (double v : vs) sum += v;
      xs.push_back(x);
      ys.push_back(sum / vs.size());
    }
    out.push_back({{"name", s}, {"x", xs}, {"y", ys}});
  }
  return {{"kind", "lines"},
          {"title", "Static map (seed 000 Figs. 8-9 style): " + metric_label + " vs " + axis},
          {"x_label", axis},
          {"y_label", metric_label},
          {"markers", true},
          {"series", out}};
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
        series.push_back({{"name", std::string(k).substr(0, std::string(k).size() - 2)}, {"x", o["t_s"]}, {"y", o[k]}});
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
