// benchctl's local commands: run specs on the embedded emulator, compare runs, with the local store.
#include "benchctl/local_commands.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>

#include "benchctl/cli_common.h"
#include "common/csv.h"
#include "benchctl/local_run.h"
#include "db/store.h"
#include "experiment/compare.h"
#include "experiment/spec.h"
#include "model/params.h"


namespace vb::benchctl {
namespace {

using vb::Status;
using vb::StatusCode;
using Json = nlohmann::ordered_json;


Json Number(double v) { return std::isfinite(v) ? Json(v) : Json(nullptr); }

Json KeyJson(const RunKey& key) {
  Json sweep = Json::array();
  for (const auto& c : key.sweep) sweep.push_back({{"field", c.field}, {"value", c.value}});
  return {{"name", key.name}, {"sweep", sweep}, {"repeat", key.repeat}};
}

Json SummaryJson(const vb::benchctl::LocalRunResult& r) {
  const auto& s = r.summary;
  Json j;
  if (r.run_id != 0) {
    j["run_id"] = r.run_id;
    j["batch_id"] = r.batch_id;
  }
  j["name"] = r.key.DisplayName();
  j["key"] = KeyJson(r.key);
  j["controller"] = r.controller;
  j["tags"] = r.tags;
  j["status"] = vb::experiment::TerminationName(s.termination);
  if (!s.message.empty()) j["message"] = s.message;
  j["duration_s"] = s.duration_s;
  j["samples"] = s.samples;
  j["ticks"] = s.ticks;
  j["wall_s"] = s.wall_s;
  j["realtime_factor"] = s.realtime_factor;
  if (s.loop.ticks > 0) {
    j["loop"] = {{"paced_ticks", s.loop.ticks},
                 {"overruns", s.loop.overruns},
                 {"jitter_p50_s", s.loop.jitter_p50_s},
                 {"jitter_p99_s", s.loop.jitter_p99_s},
                 {"jitter_max_s", s.loop.jitter_max_s}};
  }
  Json m = Json::object();
  for (const auto& [name, value] : vb::experiment::MetricList(s.metrics)) m[name] = Number(value);
  j["metrics"] = m;
  return j;
}

void PrintHuman(const vb::benchctl::LocalRunResult& r) {
  const auto& s = r.summary;
  if (r.run_id != 0) {
    std::printf("run %s [%s] (local run %lld, batch %lld): %s\n", r.key.DisplayName().c_str(), r.controller.c_str(),
                static_cast<long long>(r.run_id), static_cast<long long>(r.batch_id),
                vb::experiment::TerminationName(s.termination));
  } else {
    std::printf("run %s [%s]: %s\n", r.key.DisplayName().c_str(), r.controller.c_str(), vb::experiment::TerminationName(s.termination));
  }
  if (!s.message.empty()) std::printf("  reason: %s\n", s.message.c_str());
  std::printf("  %.6g s simulated, %zu samples, %llu control ticks, %.3g s wall, %.0fx real time\n", s.duration_s,
              s.samples, static_cast<unsigned long long>(s.ticks), s.wall_s, s.realtime_factor);
  if (s.loop.ticks > 0)
    std::printf("  loop: %llu paced ticks, %llu overruns, jitter p50 %.1f us, p99 %.1f us, max %.1f us\n",
                static_cast<unsigned long long>(s.loop.ticks), static_cast<unsigned long long>(s.loop.overruns),
                s.loop.jitter_p50_s * 1e6, s.loop.jitter_p99_s * 1e6, s.loop.jitter_max_s * 1e6);
  for (const auto& [name, value] : vb::experiment::MetricList(s.metrics))
    if (const std::string unit = vb::experiment::SiUnit(name, r.controller); std::isfinite(value))
      std::printf("  %-20s %.6g%s%s\n", name.c_str(), value, unit == "1" ? "" : " ", unit == "1" ? "" : unit.c_str());
}

// "static-map/fig8 duty=0.35 supply_pressure_Pa=200000": the sweep fields' last component.
std::string ShortName(const RunKey& key) {
  std::string out = key.name;
  char v[32];
  for (const auto& c : key.sweep) {
    std::snprintf(v, sizeof v, "%.10g", c.value);
    // Built by append: GCC 12 -O3 reports a false -Wrestrict on `" " + ...` chains.
    out.append(" ").append(c.field, c.field.rfind('.') == std::string::npos ? 0 : c.field.rfind('.') + 1).append("=").append(v);
  }
  if (key.repeat >= 0) out.append(" repeat ").append(std::to_string(key.repeat));
  return out;
}

std::string IndexedPath(const std::string& path, size_t k, size_t n) {
  if (n <= 1) return path;
  // Built by append: GCC 12 -O3 reports a false -Wrestrict on `"-" + std::to_string(k)` chains.
  const size_t dot = path.find_last_of('.');
  std::string out = dot == std::string::npos ? path : path.substr(0, dot);
  out.append("-").append(std::to_string(k));
  if (dot != std::string::npos) out.append(path, dot, std::string::npos);
  return out;
}

std::vector<vb::experiment::RunRecord> Records(const std::vector<vb::benchctl::LocalRunResult>& results) {
  std::vector<vb::experiment::RunRecord> out;
  for (const auto& r : results) {
    vb::experiment::RunRecord rec;
    rec.name = r.key.CaseName();
    rec.controller = r.controller;
    rec.ok = r.summary.ok();
    for (const auto& [name, value] : vb::experiment::MetricList(r.summary.metrics)) rec.metrics[name] = value;
    out.push_back(std::move(rec));
  }
  return out;
}

}  // namespace

int PrintComparison(const vb::experiment::Comparison& c, bool json, bool csv, const vb::experiment::TableOptions& table) {
  if (const std::string bad = vb::experiment::CheckTableOptions(c, table); !bad.empty())
    return Fail(Status::InvalidArgument(bad));
  if (json) {
    std::cout << vb::experiment::ComparisonJson(c);
  } else if (csv) {
    std::cout << vb::experiment::ComparisonCsv(c);
  } else {
    std::cout << vb::experiment::ComparisonTable(c, table);
  }
  return kExitOk;
}

int CmdCompareStored(Backend& backend, std::int64_t batch, const std::vector<std::int64_t>& run_ids, bool json,
                     bool csv, const vb::experiment::TableOptions& table) {
  auto c = backend.Compare(batch, run_ids);
  if (!c.ok()) return Fail(c.status());
  return PrintComparison(*c, json, csv, table);
}

// compare RESULTS.json (the output of `run --json`) or compare --local SPEC (runs it first).
int CmdCompare(const std::string& input, bool local, const std::string& store_path, bool json, bool csv,
               const vb::experiment::TableOptions& table) {
  if (local) {
    auto spec = vb::experiment::LoadSpecFile(input);
    if (!spec.ok()) return Fail(spec.status());
    auto results = vb::benchctl::RunLocal({{*spec}, {}, spec->name(), "", false, false, store_path});
    if (!results.ok()) return Fail(results.status().WithContext(input));
    for (const auto& r : *results)
      std::fprintf(stderr, "%s [%s]: %s\n", r.key.DisplayName().c_str(), r.controller.c_str(), r.summary.BriefReport().c_str());
    return PrintComparison(vb::experiment::Compare(Records(*results)), json, csv, table);
  }
  std::ifstream in(input);
  if (!in) return Fail(Status::NotFound(input + ": cannot open the results file"));
  Json doc;
  try {
    doc = Json::parse(in);
  } catch (const Json::exception& e) {
    return Fail(Status::InvalidArgument(input + ": not JSON: " + e.what()));
  }
  if (doc.is_object()) doc = Json::array({doc});
  std::vector<vb::experiment::RunRecord> records;
  for (size_t k = 0; k < doc.size(); ++k) {
    const Json& r = doc[k];
    const std::string where = input + ": [" + std::to_string(k) + "]";
    if (!r.is_object() || !r.contains("name") || !r["name"].is_string() || !r.contains("metrics") ||
        !r["metrics"].is_object())
      return Fail(Status::InvalidArgument(where + ": expected a run summary with 'name' and 'metrics'"));
    vb::experiment::RunRecord rec;
    // Repeats group on the run's key (written by `run --json`); a summary without one is its own case.
    rec.name = r["name"].get<std::string>();
    if (r.contains("key") && r["key"].is_object()) {
      const Json& k = r["key"];
      RunKey key{k.value("name", rec.name), {}, k.value("repeat", -1)};
      if (k.contains("sweep") && k["sweep"].is_array())
        for (const auto& c : k["sweep"])
          if (c.is_object()) key.sweep.push_back({c.value("field", ""), c.value("value", 0.0)});
      rec.name = key.CaseName();
    }
    rec.controller = r.value("controller", "");
    rec.ok = r.value("status", "done") == "done";
    for (const auto& [key, value] : r["metrics"].items()) {
      if (value.is_number()) {
        rec.metrics[key] = value.get<double>();
      } else if (!value.is_null()) {
        return Fail(Status::InvalidArgument(where + ".metrics." + key + ": not a number"));
      }
    }
    records.push_back(std::move(rec));
  }
  if (records.empty()) return Fail(Status::InvalidArgument(input + ": no runs to compare"));
  return PrintComparison(vb::experiment::Compare(records), json, csv, table);
}

// One CSV row per run: identity, the sweep point (a column per swept field), status, and every metric.
void PrintCsv(const std::vector<vb::benchctl::LocalRunResult>& results) {
  std::vector<std::string> axes;
  for (const auto& r : results)
    for (const auto& c : r.key.sweep)
      if (std::find(axes.begin(), axes.end(), c.field) == axes.end()) axes.push_back(c.field);
  std::printf("name,controller");
  for (const auto& a : axes) std::printf(",%s", CsvQuoted(a).c_str());
  std::printf(",status,duration_s,samples,wall_s");
  for (const auto& [name, value] : vb::experiment::MetricList(vb::experiment::Metrics{})) std::printf(",%s", name.c_str());
  std::printf("\n");
  for (const auto& r : results) {
    std::printf("%s,%s", CsvQuoted(r.key.DisplayName()).c_str(), r.controller.c_str());
    for (const auto& a : axes) {
      std::printf(",");
      for (const auto& c : r.key.sweep)
        if (c.field == a) std::printf("%.10g", c.value);
    }
    std::printf(",%s,%.9g,%zu,%.6g", vb::experiment::TerminationName(r.summary.termination), r.summary.duration_s,
                r.summary.samples, r.summary.wall_s);
    for (const auto& [name, value] : vb::experiment::MetricList(r.summary.metrics)) {
      if (std::isfinite(value)) {
        std::printf(",%.10g", value);
      } else {
        std::printf(",");
      }
    }
    std::printf("\n");
  }
}

int CmdRun(const std::string& spec_path, bool local, const std::string& store_path, const std::string& trace_csv,
           bool json, bool csv, bool realtime, const vb::experiment::TableOptions& table) {
  if (!local) {
    return Fail(Status::FailedPrecondition(
        "no server given: use --local for the embedded emulator, or --server ADDR (or VALVEBENCH_SERVER)"));
  }
  auto spec = vb::experiment::LoadSpecFile(spec_path);
  if (!spec.ok()) return Fail(spec.status());
  auto results = vb::benchctl::RunLocal({{*spec}, {}, spec->name(), "", realtime, !trace_csv.empty(), store_path});
  if (!results.ok()) return Fail(results.status().WithContext(spec_path));
  int exit_code = kExitOk;
  Json all = Json::array();
  for (size_t k = 0; k < results->size(); ++k) {
    const auto& r = (*results)[k];
    if (!r.summary.ok()) exit_code = kExitRunFailed;
    if (!trace_csv.empty()) {
      auto st = vb::benchctl::WriteTraceCsv(r.trace, IndexedPath(trace_csv, k, results->size()));
      if (!st.ok()) return Fail(st);
    }
    if (json) {
      all.push_back(SummaryJson(r));
    } else if (!csv && results->size() == 1) {
      PrintHuman(r);
    } else if (!csv) {  // a batch: one line per run, the metrics are in the comparison below
      std::printf("run %s%s: %s\n", r.run_id != 0 ? (std::to_string(r.run_id) + " ").c_str() : "",
                  ShortName(r.key).c_str(), vb::experiment::TerminationName(r.summary.termination));
    }
  }
  if (csv && !json) {
    PrintCsv(*results);
  } else if (json) {
    std::cout << (all.size() == 1 ? all[0] : all).dump(2) << "\n";
  } else if (results->size() > 1) {
    const auto c = vb::experiment::Compare(Records(*results));
    if (const std::string bad = vb::experiment::CheckTableOptions(c, table); !bad.empty())
      return Fail(Status::InvalidArgument(bad));
    std::cout << "\n" << vb::experiment::ComparisonTable(c, table);
  }
  return exit_code;
}

}  // namespace vb::benchctl
