// benchctl report: gathers runs, traces, regression results or a diagnosis and writes report/'s HTML page.
#include "benchctl/report_commands.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>

#include "benchctl/cli_common.h"
#include "db/store.h"
#include "proto/api_convert.h"
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

// What a report needs of one run, wherever it came from.
struct RunInfo {
  std::int64_t id = 0;
  RunKey key;
  std::string controller;
  bool ok = true;
  std::map<std::string, double> metrics;
};

Json BatchSections(const std::string& where, std::int64_t batch, const std::vector<RunInfo>& runs,
                   const std::vector<report::TraceData>& traces) {
  Json sections = Json::array();
  std::vector<experiment::RunRecord> recs;
  std::vector<report::MapPoint> map;
  for (const auto& r : runs) {
    recs.push_back({r.key.CaseName(), r.controller, r.ok, r.metrics});
    auto it = r.metrics.find("mean_position_pct");
    if (r.ok && it != r.metrics.end()) map.push_back({r.key, it->second});
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

report::TraceData FromChunks(const std::string& label, const std::string& controlled,
                             const std::vector<db::TraceChunk>& chunks) {
  report::TraceData t;
  t.label = label;
  t.controlled = controlled;
  if (chunks.empty()) return t;
  t.t0_s = chunks.front().t0_s;
  t.sample_period_s = chunks.front().sample_period_s;
  for (const auto& c : chunks)
    for (std::size_t ch = 0; ch < c.channels.size(); ++ch) {
      auto& col = t.channels[c.channels[ch]];
      col.insert(col.end(), c.data.begin() + static_cast<std::ptrdiff_t>(ch * c.samples),
                 c.data.begin() + static_cast<std::ptrdiff_t>((ch + 1) * c.samples));
    }
  return t;
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

StatusOr<std::vector<RunInfo>> LocalRuns(db::Store& store, std::int64_t batch, std::int64_t run) {
  std::vector<db::RunRecord> recs;
  if (run != 0) {
    auto r = store.GetRun(run);
    if (!r.ok()) return r.status();
    recs.push_back(*r);
  } else {
    db::RunFilter f;
    f.batch_id = batch;
    f.limit = 1000;
    for (;;) {
      auto page = store.ListRuns(f);
      if (!page.ok()) return page.status();
      recs.insert(recs.end(), page->begin(), page->end());
      if (static_cast<int>(page->size()) < f.limit) break;
      f.after_id = page->back().id;
    }
    if (recs.empty()) return Status::NotFound("batch " + std::to_string(batch) + " not found in the local store");
  }
  std::vector<RunInfo> out;
  for (const auto& r : recs) {
    RunInfo i{r.id, r.key, r.controller, r.status == db::RunStatus::kDone, {}};
    auto m = store.GetMetrics(r.id);
    if (!m.ok()) return m.status();
    for (const auto& x : *m) i.metrics[x.name] = x.value;
    out.push_back(std::move(i));
  }
  return out;
}

StatusOr<std::vector<RunInfo>> RemoteRuns(client::Client& c, std::int64_t batch, std::int64_t run) {
  std::vector<RunInfo> out;
  auto add = [&](const v1::Run& r) {
    RunInfo i{r.id(), api::FromProto(r.key()), r.controller(), r.status() == v1::DONE, {}};
    for (const auto& [k, v] : r.metrics()) i.metrics[k] = v;
    out.push_back(std::move(i));
  };
  if (run != 0) {
    auto r = c.GetRun(run);
    if (!r.ok()) return r.status();
    add(*r);
    return out;
  }
  v1::ListRunsRequest req;
  req.set_batch_id(batch);
  req.set_page_size(1000);
  for (;;) {
    auto resp = c.ListRuns(req);
    if (!resp.ok()) return resp.status();
    for (const auto& r : resp->runs()) add(r);
    if (resp->next_page_token().empty()) break;
    req.set_page_token(resp->next_page_token());
  }
  if (out.empty()) return Status::NotFound("batch " + std::to_string(batch) + " not found on the server");
  return out;
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
  report_->add_option("--diagnosis", diagnosis_, "a gap diagnosis JSON file (benchctl diagnose --json FILE)");
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
    std::vector<RunInfo> runs;
    std::vector<report::TraceData> traces;
    std::string where;
    if (server.empty()) {
      if (store_path.empty()) return Fail(Status::InvalidArgument("--batch/--run locally need the local store (--db)"));
      auto store = db::Store::Open(store_path);
      if (!store.ok()) return Fail(store.status().WithContext("local store " + store_path));
      auto r = LocalRuns(**store, batch_, run_);
      if (!r.ok()) return Fail(r.status());
      runs = std::move(*r);
      for (std::size_t k = 0; k < runs.size() && static_cast<int>(k) < max_traces_; ++k) {
        auto chunks = (*store)->ReadTrace(runs[k].id);
        if (!chunks.ok()) return Fail(chunks.status());
        traces.push_back(FromChunks("run " + std::to_string(runs[k].id) + ": " + runs[k].key.DisplayName(),
                                    Controlled(runs[k].controller), *chunks));
      }
      where = "local store";
    } else {
      auto c = make_client();
      auto r = RemoteRuns(*c, batch_, run_);
      if (!r.ok()) return Fail(r.status());
      runs = std::move(*r);
      for (std::size_t k = 0; k < runs.size() && static_cast<int>(k) < max_traces_; ++k) {
        if (!runs[k].ok) continue;
        auto t = c->GetTrace(runs[k].id);
        if (!t.ok()) return Fail(t.status());
        traces.push_back(FromFetched("run " + std::to_string(runs[k].id) + ": " + runs[k].key.DisplayName(),
                                     Controlled(runs[k].controller), *t));
      }
      where = "server " + server;
    }
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
