// benchctl report: gathers runs, traces, regression results or a diagnosis and writes report/'s HTML page.
#include "benchctl/report_commands.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>

#include "benchctl/backend.h"
#include "benchctl/cli_common.h"
#include "experiment/compare.h"
#include "experiment/metrics.h"
#include "experiment/spec.h"
#include "report/report.h"

namespace vb::benchctl {
namespace {

namespace v1 = valvebench::v1;
using report::Json;

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
  report_->add_option("--regress", regress_,
                      "a stored regression result (benchctl regress, or a night): the server's, or the local store's");
  report_->add_option("--diagnosis", diagnosis_, "a gap diagnosis JSON file (benchctl diagnose --json-out FILE, or --json > FILE)");
  report_->add_option("--html", html_, "output HTML file")->required();
  report_->add_option("--max-traces", max_traces_, "traces of at most this many runs (default 100)")
      ->check(CLI::Range(0, 1000));
  report_->add_option("--svg", svg_dir_, "also write every plot as DIR/NN-<heading>.svg (headless chromium)");
  report_->add_option("--png", png_dir_, "also write every plot as DIR/NN-<heading>.png (headless chromium)");
  report_->add_flag("--local", local_, "runs from the local store even if a server is configured");
  report_->add_flag("--json", *shared_.json, "print {html, sections} as JSON");
  AddServerOptions(report_, shared_);
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
    // A result kept by benchctl regress or a night: the server's with --server, else the local store's.
    if (server.empty() && store_path.empty())
      return Fail(Status::InvalidArgument("--regress with --no-store: no regression result is kept there (--db)"));
    auto backend = ChooseBackend(server, store_path, make_client);
    auto rec = backend->GetRegression(regress_);
    if (!rec.ok()) return Fail(rec.status());
    Json r;
    try {
      r = Json::parse(rec->result_json());
    } catch (const Json::exception& e) {
      return Fail(Status::DataLoss("regression " + std::to_string(regress_) + " in " + backend->Where() +
                                   ": stored result is not JSON"));
    }
    title = "Regression " + std::to_string(regress_) + ": suite " + rec->suite() +
            (rec->night().empty() ? "" : ", night " + rec->night());
    sections = report::RegressionSections(r);
  } else {
    if (server.empty() && store_path.empty())
      return Fail(Status::InvalidArgument("--batch/--run locally need the local store (--db)"));
    auto backend = ChooseBackend(server, store_path, make_client);
    // Gathered as the web's batch report gathers them (client/report_runs.h): no trace before a run ends.
    auto fetched = run_ != 0 ? backend->ReportRuns(0, {run_}, {max_traces_, 0})
                             : backend->ReportRuns(batch_, {}, {max_traces_, 0});
    if (!fetched.ok()) return Fail(fetched.status());
    const std::vector<report::RunInfo>& runs = fetched->runs;
    const std::string where = backend->Where();
    if (run_ != 0) {
      title = "Run " + std::to_string(run_) + ": " + runs.front().key.DisplayName();
      sections = report::RunSections(where, runs.front());
    } else {
      title = client::BatchReportTitle(batch_, runs);
      sections = report::BatchSections(where, batch_, runs);
    }
  }
  std::ofstream out(html_);
  out << report::RenderHtml(title, sections);
  out.close();
  if (!out) return Fail(Status::Unavailable(html_ + ": cannot write"));
  std::vector<std::string> exported;
  if (!svg_dir_.empty() || !png_dir_.empty()) {
    auto files = report::ExportPlots(html_, svg_dir_, png_dir_);
    if (!files.ok()) return Fail(files.status());
    exported = *files;
  }
  if (*shared_.json) {
    std::cout << Json{{"html", html_}, {"title", title}, {"sections", sections.size()}, {"plots", exported}}.dump(2)
              << "\n";
  } else {
    std::printf("%s: %s (%zu sections)\n", html_.c_str(), title.c_str(), sections.size());
    if (!exported.empty()) std::printf("%zu plot files in %s\n", exported.size(), (svg_dir_.empty() ? png_dir_ : svg_dir_).c_str());
  }
  return kExitOk;
}

}  // namespace vb::benchctl
