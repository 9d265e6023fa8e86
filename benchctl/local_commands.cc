// benchctl compare: results files, a spec run on a service (--local: the local service), or stored runs.
#include "benchctl/local_commands.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>

#include "benchctl/cli_common.h"
#include "client/run_key_json.h"
#include "common/csv.h"
#include "experiment/compare.h"
#include "experiment/spec.h"
#include "model/params.h"


namespace vb::benchctl {
namespace {

using vb::Status;
using vb::StatusCode;
using Json = nlohmann::ordered_json;


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

int CmdCompareSpec(Backend& backend, const std::string& spec_path, bool json, bool csv,
                   const vb::experiment::TableOptions& table) {
  auto spec = vb::experiment::LoadSpecFile(spec_path);
  if (!spec.ok()) return Fail(spec.status());
  auto sub = backend.Submit(*spec, false);
  if (!sub.ok()) return Fail(sub.status().WithContext(spec_path));
  Status shown;  // the first run that could not be read back
  auto st = backend.WaitForRuns(sub->run_ids, [&](std::int64_t id) {
    auto r = backend.GetRun(id);
    if (!r.ok()) {
      if (shown.ok()) shown = r.status();
      return;
    }
    std::fprintf(stderr, "%s [%s]: %s\n", r->key.DisplayName().c_str(), r->controller.c_str(),
                 ExecutionBrief(*r).c_str());
  });
  if (!st.ok()) return Fail(st);
  if (!shown.ok()) return Fail(shown);
  auto c = backend.Compare(sub->batch_id, {});
  if (!c.ok()) return Fail(c.status());
  return PrintComparison(*c, json, csv, table);
}

// compare RESULTS.json (the output of `run --json`).
int CmdCompare(const std::string& input, bool json, bool csv, const vb::experiment::TableOptions& table) {
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
    rec.key = vb::NamedRun(r["name"].get<std::string>());
    if (r.contains("key")) {
      auto key = vb::client::RunKeyFromJson(r["key"], where + ".key", rec.key.name);
      if (!key.ok()) return Fail(key.status());
      rec.key = std::move(*key);
    }
    rec.controller = r.value("controller", "");
    auto status = vb::ParseRunStatus(r.value("status", std::string(vb::RunStatusName(vb::RunStatus::kDone))));
    if (!status.ok()) return Fail(status.status().WithContext(where + ".status"));
    rec.ok = *status == vb::RunStatus::kDone;
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

}  // namespace vb::benchctl
