// benchctl report: gathers runs, traces, regression results or a diagnosis and writes report/'s HTML page.
#include "benchctl/report_commands.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>

#include "benchctl/backend.h"
#include "benchctl/cli_common.h"
#include "db/store.h"
#include "experiment/compare.h"
#include "experiment/metrics.h"
#include "report/report.h"

namespace vb::benchctl {
namespace {

namespace v1 = valvebench::v1;
using report::Json;

std::string Controlled(const std::string& controller) {
  auto ends = [&](const char* s) {
    const std::string suf(s);
    return controller.size() >= suf.size() && controller.compare(controller.size() - suf.size(), suf.size(), suf) == 0;
  };
  if (ends("_current") || controller == "peak_and_hold") return "current";
  if (ends("_position")) return "position";
  return "";
}

Json BatchSections(const std::string& where, std::int64_t batch, const std::vector<RunView>& runs,
                   const std::vector<report::TraceData>& traces) {
  Json sections = Json::array();
  std::vector<experiment::RunRecord> recs;
  std::vector<report::MapPoint> map;
  for (const auto& r : runs) {
    recs.push_back({r.key.CaseName(), r.controller, r.ok(), r.metrics});
    auto it = r.metrics.find("mean_position_pct");
    if (r.ok() && it != r.metrics.end()) map.push_back({r.key, it->second});
  }
  sections.push_back({{"kind", "note"},
                      {"text", "Batch " + std::to_string(batch) + " (" + where + "): " + std::to_string(runs.size()) +
                                   " runs. Repeats are grouped: mean \u00b1 sample standard deviation."}});
  for (auto& s : report::ComparisonSections(experiment::Compare(recs), "Comparison (ranked by RMSE)"))
    sections.push_back(s);
  Json m = report::StaticMapSection(map, "mean_position_pct [%]");
  if (!m.is_null()) sections.push_back(m);
  sections.push_back(report::TraceSection(traces));
  return sections;
}

report::TraceData FromFetched(const std::string& label, const std::string& controlled, const client::FetchedTrace& f) {
  report::TraceData t;
  t.label = label;
  t.controlled = controlled;
  t.t0_s = f.t0_s;
  t.sample_period_s = f.sample_period_s;
  t.channels = f.columns;
  return t;
}

StatusOr<Json> ReadJsonFile(const std::string& path, const std::string& flag) {
  std::ifstream in(path);
  if (!in) return Status::NotFound(flag + ": cannot open '" + path + "'");
  try {
    return Json::parse(in);
  } catch (const Json::exception& e) {
    return Status::InvalidArgument(flag + " " + path + ": not JSON: " + e.what());
  }
}

}  // namespace

ReportCli::ReportCli(CLI::App* app, SharedOptions shared) : shared_(shared) {
  report_ = app->add_subcommand("report", "a self-contained HTML report: traces, comparison, maps, regressions");
  report_->add_option("--batch", batch_, "the runs of this batch: comparison, Pareto scatter, static map, traces");
  report_->add_option("--run", run_, "one run: its traces and metrics");
  report_->add_option("--regress", regress_, "a regression result stored by benchctl regress (local store)");
  report_->add_option("--diagnosis", diagnosis_, "a gap diagnosis JSON file (benchctl diagnose --json-out FILE, or --json > FILE)");
  report_->add_option("--html", html_, "output HTML file")->required();
  report_->add_option("--max-traces", max_traces_, "traces of at most this many runs (default 4)")
      ->check(CLI::Range(0, 100));
  report_->add_flag("--local", local_, "runs from the local store even if a server is configured");
  report_->add_flag("--json", *shared_.json, "print {html, sections} as JSON");
  report_->add_option("--server", *shared_.server, "bench server address host:port (or VALVEBENCH_SERVER)");
  report_->add_option("--token", *shared_.token, "bearer token (or VALVEBENCH_TOKEN)");
  report_->add_option("--tls-ca", *shared_.tls_ca_file, "PEM file of the CA that signed the server's certificate");
  report_->add_option("--db", *shared_.store_path, "local store");
}

int ReportCli::Run(const ClientFactory& make_client) {
  const int given = (batch_ != 0) + (run_ != 0) + (regress_ != 0) + (!diagnosis_.empty());
  if (given != 1)
    return Fail(Status::InvalidArgument("report: give exactly one of --batch, --run, --regress, --diagnosis"));
  const std::string server = local_ ? "" : *shared_.server;
  const std::string& store_path = *shared_.store_path;
  std::string title;
  Json sections = Json::array();

  if (!diagnosis_.empty()) {
    auto j = ReadJsonFile(diagnosis_, "--diagnosis");
    if (!j.ok()) return Fail(j.status());
    title = "Gap diagnosis: " + diagnosis_;
    sections = report::DiagnosisSections(*j);
  } else if (regress_ != 0) {
    if (store_path.empty()) return Fail(Status::InvalidArgument("--regress needs the local store (--db)"));
    auto store = db::Store::Open(store_path);
    if (!store.ok()) return Fail(store.status().WithContext("local store " + store_path));
    auto rec = (*store)->GetRegression(regress_);
    if (!rec.ok()) return Fail(rec.status());
    Json r;
    try {
      r = Json::parse(rec->result_json);
    } catch (const Json::exception& e) {
      return Fail(Status::DataLoss("regression " + std::to_string(regress_) + ": stored result is not JSON"));
    }
    title = "Regression " + std::to_string(regress_) + ": suite " + rec->suite +
            (rec->night.empty() ? "" : ", night " + rec->night);
    sections = report::RegressionSections(r);
  } else {
    if (server.empty() && store_path.empty())
      return Fail(Status::InvalidArgument("--batch/--run locally need the local store (--db)"));
    auto backend = ChooseBackend(server, store_path, make_client);
    auto fetched = run_ != 0 ? backend->Runs(0, {run_}) : backend->Runs(batch_, {});
    if (!fetched.ok()) return Fail(fetched.status());
    const std::vector<RunView>& runs = *fetched;
    std::vector<report::TraceData> traces;
    for (std::size_t k = 0; k < runs.size() && static_cast<int>(k) < max_traces_; ++k) {
      if (!runs[k].ended()) continue;  // no trace is stored before a run ends
      auto t = backend->GetTrace(runs[k].id);
      if (!t.ok()) return Fail(t.status());
      traces.push_back(FromFetched("run " + std::to_string(runs[k].id) + ": " + runs[k].key.DisplayName(),
                                   Controlled(runs[k].controller), *t));
    }
    const std::string where = server.empty() ? "local store" : "server " + server;
    if (run_ != 0) {
      title = "Run " + std::to_string(run_) + ": " + runs.front().key.DisplayName();
      std::vector<std::pair<std::string, double>> m(runs.front().metrics.begin(), runs.front().metrics.end());
      sections.push_back(report::TraceSection(traces));
      sections.push_back(report::MetricsSection("Metrics (docs/metrics.md)", m));
    } else {
      title = "Batch " + std::to_string(batch_);
      sections = BatchSections(where, batch_, runs, traces);
    }
  }
  std::ofstream out(html_);
  out << report::RenderHtml(title, sections);
  out.close();
  if (!out) return Fail(Status::Unavailable(html_ + ": cannot write"));
  if (*shared_.json) {
    std::cout << Json{{"html", html_}, {"title", title}, {"sections", sections.size()}}.dump(2) << "\n";
  } else {
    std::printf("%s: %s (%zu sections)\n", html_.c_str(), title.c_str(), sections.size());
  }
  return kExitOk;
}

}  // namespace vb::benchctl
