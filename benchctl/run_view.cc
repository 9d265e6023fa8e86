#include "benchctl/run_view.h"

#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <set>

#include <fmt/format.h>

#include "client/run_key_json.h"
#include "common/csv.h"
#include "common/format.h"
#include "experiment/compare.h"
#include "common/units.h"
#include "experiment/metrics.h"

namespace vb::benchctl {
namespace {

Json Number(double v) { return std::isfinite(v) ? Json(v) : Json(nullptr); }

// A stored run's execution under the JSON names `run --json` has always used (docs/cli.md).
Json SummaryJson(const RunView& r) {
  const auto& x = *r.execution;
  const double factor = x.wall_s() > 0.0 ? x.simulated_s() / x.wall_s() : 0.0;
  Json j = {{"termination", RunStatusName(r.status)},
            {"duration_s", x.simulated_s()},
            {"samples", x.samples()},
            {"ticks", x.control_ticks()},
            {"wall_s", x.wall_s()},
            {"realtime_factor", factor},
            {"metrics_from", x.metrics_from_trajectory() ? "trajectory" : "samples"}};
  if (!x.build().empty()) j["build"] = x.build();
  if (x.has_loop()) {
    const auto& l = x.loop();
    j["loop"] = {{"paced_ticks", l.ticks()},
                 {"overruns", l.overruns()},
                 {"jitter_p50_s", l.jitter_p50_s()},
                 {"jitter_p99_s", l.jitter_p99_s()},
                 {"jitter_max_s", l.jitter_max_s()}};
  }
  return j;
}

Json Time(double unix_s) { return unix_s > 0.0 ? Json(IsoLocalTime(unix_s)) : Json(nullptr); }

// Built by fmt/append: GCC 12 -O3 reports a false -Wrestrict on `" " + std::string` chains.
std::string Percent(double progress) { return fmt::format("{:.0f} %", 100.0 * progress); }

}  // namespace

std::vector<std::pair<std::string, double>> OrderedMetrics(const std::map<std::string, double>& metrics) {
  std::vector<std::pair<std::string, double>> out;
  std::set<std::string> taken;
  for (const auto& [name, unused] : experiment::MetricList(experiment::Metrics{})) {
    auto it = metrics.find(name);
    if (it == metrics.end()) continue;
    out.emplace_back(name, it->second);
    taken.insert(name);
  }
  for (const auto& [name, v] : metrics)  // std::map: alphabetical
    if (!taken.count(name)) out.emplace_back(name, v);
  return out;
}

std::string IsoLocalTime(double unix_s) {
  if (!(unix_s > 0.0)) return "-";
  const std::time_t t = static_cast<std::time_t>(std::floor(unix_s));
  std::tm tm{};
  localtime_r(&t, &tm);
  char buf[40];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%S", &tm);
  const long off_min = tm.tm_gmtoff / 60;  // ISO 8601's extended offset, +hh:mm (strftime's %z has no colon)
  const long a = off_min < 0 ? -off_min : off_min;
  return fmt::format("{}{}{:02}:{:02}", buf, off_min < 0 ? '-' : '+', a / 60, a % 60);
}

std::string RunText(const RunView& r, bool history) {
  std::string out;
  if (r.id != 0) {
    out += fmt::format("run {} {} [{}] (batch {}): {}", r.id, r.key.DisplayName(), r.controller, r.batch_id,
                       RunStatusName(r.status));
  } else {
    out += fmt::format("run {} [{}]: {}", r.key.DisplayName(), r.controller, RunStatusName(r.status));
  }
  if (r.status == RunStatus::kRunning && r.result_waiting_since_unix_s > 0.0)
    out += ", result waiting for the store since " + IsoLocalTime(r.result_waiting_since_unix_s);
  else if (r.status == RunStatus::kRunning)
    out.append(" ").append(Percent(r.progress));
  out += "\n";
  if (!r.reason.empty()) out += "  reason: " + r.reason + "\n";
  if (r.id != 0) {
    out += fmt::format("  bench {}{}, submitter {}, priority {}\n", r.bench.empty() ? "any" : r.bench,
                       r.host.empty() ? "" : " on host " + r.host, r.submitter.empty() ? "-" : r.submitter,
                       r.priority);
    out += "  submitted " + IsoLocalTime(r.submitted_unix_s);
    if (r.started_unix_s > 0.0) out += ", started " + IsoLocalTime(r.started_unix_s);
    if (r.finished_unix_s > 0.0) {
      out += ", finished " + IsoLocalTime(r.finished_unix_s);
      if (r.started_unix_s > 0.0) out += fmt::format(" ({:.3g} s)", r.finished_unix_s - r.started_unix_s);
    }
    out += "\n";
  }
  if (r.execution) {
    const auto& x = *r.execution;
    const double factor = x.wall_s() > 0.0 ? x.simulated_s() / x.wall_s() : 0.0;
    out += fmt::format("  {:.6g} s simulated, {} samples, {} control ticks, {:.3g} s wall, {:.0f}x real time\n",
                       x.simulated_s(), x.samples(), x.control_ticks(), x.wall_s(), factor);
    if (x.has_loop())
      out += fmt::format("  loop: {} paced ticks, {} overruns, jitter p50 {:.1f} us, p99 {:.1f} us, max {:.1f} us\n",
                         x.loop().ticks(), x.loop().overruns(), x.loop().jitter_p50_s() * 1e6,
                         x.loop().jitter_p99_s() * 1e6, x.loop().jitter_max_s() * 1e6);
    if (!x.build().empty()) out += fmt::format("  build: {}\n", x.build());
  }
  // With its unit and SI prefix, as the web's run page writes it (common/units.h): "rmse  953.3 µA".
  for (const auto& [name, value] : OrderedMetrics(r.metrics))
    if (std::isfinite(value))
      out += fmt::format("  {:<20} {}\n", name, FormatQuantity(value, experiment::SiUnit(name, r.controller)));
  if (history)
    for (const auto& h : r.history)
      out += fmt::format("  history: {:<11} {}{}{}\n", RunStatusName(h.status), IsoLocalTime(h.at_unix_s),
                         h.reason.empty() ? "" : "  ", h.reason);
  return out;
}

Json RunJson(const RunView& r) {
  Json j;
  if (r.id != 0) {
    j["id"] = r.id;
    j["batch_id"] = r.batch_id;
  }
  j["name"] = r.key.DisplayName();
  j["key"] = client::RunKeyJson(r.key);
  j["controller"] = r.controller;
  j["status"] = RunStatusName(r.status);
  j["reason"] = r.reason;
  if (r.id != 0) {
    j["bench"] = r.bench;
    if (!r.host.empty()) j["host"] = r.host;
    j["submitter"] = r.submitter;
    j["priority"] = r.priority;
    j["progress"] = r.progress;
    if (r.result_waiting_since_unix_s > 0.0) j["result_waiting_since_unix_s"] = r.result_waiting_since_unix_s;
    j["submitted"] = Time(r.submitted_unix_s);
    j["started"] = Time(r.started_unix_s);
    j["finished"] = Time(r.finished_unix_s);
    j["submitted_unix_s"] = r.submitted_unix_s;
    j["started_unix_s"] = r.started_unix_s;
    j["finished_unix_s"] = r.finished_unix_s;
    j["tags"] = r.tags;
  }
  if (!r.split.empty()) j["split"] = r.split;
  if (r.t_start_s) j["t_start_s"] = *r.t_start_s;
  if (r.execution) j["summary"] = SummaryJson(r);
  Json m = Json::object();
  for (const auto& [name, value] : OrderedMetrics(r.metrics)) m[name] = Number(value);
  j["metrics"] = m;
  if (!r.history.empty()) {
    Json h = Json::array();
    for (const auto& c : r.history)
      h.push_back({{"status", RunStatusName(c.status)}, {"at", Time(c.at_unix_s)}, {"at_unix_s", c.at_unix_s},
                   {"reason", c.reason}});
    j["history"] = h;
  }
  if (r.spec) {
    std::string text;
    google::protobuf::util::JsonPrintOptions o;
    o.preserve_proto_field_names = true;
    (void)google::protobuf::util::MessageToJsonString(*r.spec, &text, o);
    j["spec"] = Json::parse(text, nullptr, false);
  }
  return j;
}

std::string RunsCsv(const std::vector<RunView>& runs) {
  // Metric columns: experiment::MetricList's, then any other name a run has, so rows of one list line up.
  std::map<std::string, double> all;
  for (const auto& [name, unused] : experiment::MetricList(experiment::Metrics{})) all[name] = 0.0;
  for (const auto& r : runs)
    for (const auto& [name, v] : r.metrics) all[name] = v;
  std::vector<std::string> columns;
  for (const auto& [name, unused] : OrderedMetrics(all)) columns.push_back(name);

  // The sweep point as columns (one per swept field, in order of first appearance), so a static map's CSV
  // reads as position against duty per pressure without parsing the name.
  std::vector<std::string> axes;
  for (const auto& r : runs)
    for (const auto& c : r.key.sweep)
      if (std::find(axes.begin(), axes.end(), c.field) == axes.end()) axes.push_back(c.field);

  std::string out = "id,batch_id,name,controller";
  for (const auto& a : axes) out.append(",").append(CsvQuoted(a));
  out += ",status,bench,progress,duration_s,samples,wall_s";
  // Metric headers carry their unit (rmse_A, iae_A_s): the values are SI.
  const std::string law = runs.empty() ? "" : runs.front().controller;
  for (const auto& c : columns) out.append(",").append(experiment::MetricColumnName(c, law));
  out += "\n";
  for (std::size_t k = 0; k < runs.size(); ++k) {
    const RunView& r = runs[k];
    out += r.id != 0 ? fmt::format("{},{}", r.id, r.batch_id) : std::string(",");
    out += fmt::format(",{},{}", CsvQuoted(r.key.DisplayName()), r.controller);
    for (const auto& a : axes) {
      out += ",";
      for (const auto& c : r.key.sweep)
        if (c.field == a) out += fmt::format("{:.10g}", c.value);
    }
    out += fmt::format(",{},{},{:.3f}", RunStatusName(r.status), CsvQuoted(r.bench), r.progress);
    out += r.execution ? fmt::format(",{:.9g},{},{:.6g}", r.execution->simulated_s(), r.execution->samples(),
                                     r.execution->wall_s())
                       : std::string(",,,");
    for (const auto& c : columns) {
      auto it = r.metrics.find(c);
      out += it != r.metrics.end() && std::isfinite(it->second) ? fmt::format(",{:.10g}", it->second) : ",";
    }
    out += "\n";
  }
  return out;
}

std::string RunLine(const RunView& r) {
  // The sweep fields' last component: "static-map/fig8 duty=0.35 supply_pressure_Pa=200000".
  std::string name = r.key.name;
  for (const auto& c : r.key.sweep) {
    const auto dot = c.field.rfind('.');
    name.append(" ").append(c.field, dot == std::string::npos ? 0 : dot + 1).append(fmt::format("={:.10g}", c.value));
  }
  if (r.key.repeat >= 0) name.append(" repeat ").append(std::to_string(r.key.repeat));
  std::string out = r.id != 0 ? fmt::format("run {} {}: {}", r.id, name, RunStatusName(r.status))
                              : fmt::format("run {}: {}", name, RunStatusName(r.status));
  if (!r.reason.empty()) out.append(" (").append(r.reason).append(")");
  out.append("\n");
  return out;
}

std::string ExecutionBrief(const RunView& r) {
  if (!r.execution) return RunStatusName(r.status);
  const auto& x = *r.execution;
  const double factor = x.wall_s() > 0.0 ? x.simulated_s() / x.wall_s() : 0.0;
  std::string s = fmt::format("{}: {:g} s, {} samples, {} ticks, {:g}x real time", RunStatusName(r.status),
                              x.simulated_s(), x.samples(), x.control_ticks(), factor);
  if (!r.reason.empty()) s.append(" (").append(r.reason).append(")");
  return s;
}

std::string EventText(const RunView& r) {
  std::string s = fmt::format("run {} {}", r.id, RunStatusName(r.status));
  if (r.status == RunStatus::kRunning) s.append(" ").append(Percent(r.progress));
  if (!r.reason.empty()) s += " (" + r.reason + ")";
  return s;
}

}  // namespace vb::benchctl
