// benchctl: the valvebench command line.
//
// Local mode (--local): a local service (the embedded emulator, the local store) in this process, reached
// through its in-process channel exactly as a server is (benchctl/backend.h); no server. Remote mode (--server ADDR or VALVEBENCH_SERVER,
// --token TOKEN or VALVEBENCH_TOKEN): a valvebench-server. Data on stdout, progress on stderr; --json everywhere.
// Exit codes (benchctl/cli_common.h): 0 success; 1 a run failed or was cancelled; 2 the request was refused
// (bad input naming the field, not found, no capable bench, limits, permissions); 3 environment.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <vector>
#include <set>
#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>
#include <iostream>

#include "common/edit_distance.h"
#include "benchctl/cli_common.h"
#include "benchctl/gap_commands.h"
#include "benchctl/hw_commands.h"
#include "benchctl/local_commands.h"
#include "benchctl/backend.h"
#include "benchctl/db_commands.h"
#include "benchctl/prune_command.h"
#include "benchctl/regress_commands.h"
#include "benchctl/report_commands.h"
#include "benchctl/run_commands.h"

#include <fstream>
#include <sstream>

namespace {

using vb::Status;
using vb::benchctl::Fail;
using vb::benchctl::kExitBadInput;
using vb::benchctl::kExitOk;

}  // namespace

// "did you mean --metrics?" for a misspelt long option (issue 37): the closest option any command has, by
// edit distance, when it is within a third of the name (at least 2 edits): close enough to be a typo, far
// enough that unrelated options are not offered.
namespace {
void CollectOptions(const CLI::App* app, std::set<std::string>* names) {
  for (const CLI::Option* o : app->get_options())
    for (const auto& n : o->get_lnames()) names->insert(n);
  for (const CLI::App* sub : app->get_subcommands([](const CLI::App*) { return true; })) CollectOptions(sub, names);
}

void SuggestOption(const CLI::App& app, int argc, char** argv) {
  std::set<std::string> names;
  CollectOptions(&app, &names);
  for (int k = 1; k < argc; ++k) {
    std::string arg = argv[k];
    if (arg.rfind("--", 0) != 0 || arg.size() < 3) continue;
    arg = arg.substr(2, arg.find('=') == std::string::npos ? std::string::npos : arg.find('=') - 2);
    if (names.count(arg)) continue;
    std::string best;
    std::size_t best_d = std::max<std::size_t>(2, arg.size() / 3) + 1;
    for (const auto& n : names)
      if (const std::size_t d = vb::EditDistance(arg, n); d < best_d) {
        best_d = d;
        best = n;
      }
    if (!best.empty()) std::fprintf(stderr, "benchctl: unknown option --%s: did you mean --%s?\n", arg.c_str(), best.c_str());
  }
}
}  // namespace

int main(int argc, char** argv) {
  // What the in-process run pipeline (runs/) logs goes to stderr, next to benchctl's own messages; stdout is data.
  spdlog::set_default_logger(spdlog::stderr_logger_mt("benchctl"));
  spdlog::set_pattern("benchctl: %v");
  CLI::App app{"benchctl: run, watch and compare experiments on valvebench benches"};
  app.require_subcommand(1);
  bool json = false, csv = false;
  std::string server, token, tls_ca_file;
  if (const char* v = std::getenv("VALVEBENCH_SERVER")) server = v;
  if (const char* v = std::getenv("VALVEBENCH_TOKEN")) token = v;
  app.add_flag("--json", json, "machine-readable output on stdout");
  app.add_option("--server", server, "bench server address host:port (or VALVEBENCH_SERVER)");
  app.add_option("--token", token, "bearer token (or VALVEBENCH_TOKEN)");
  app.add_option("--tls-ca", tls_ca_file, "PEM file of the CA that signed the server's certificate (TLS)");
  auto common = [&](CLI::App* sub, bool with_csv) {
    sub->add_flag("--json", json, "machine-readable output on stdout");
    if (with_csv) sub->add_flag("--csv", csv, "CSV output on stdout");
    vb::benchctl::AddServerOptions(sub, &server, &token, &tls_ca_file);
  };

  std::string spec_path, trace_csv;
  bool local = false, realtime = false, wait = false;
  std::string store_path = vb::benchctl::DefaultLocalStorePath();
  bool no_store = false;
  auto local_store = [&](CLI::App* sub) {
    sub->add_option("--db", store_path, "local store for --local runs: a SQLite file or postgresql://... "
                                        "(default $VALVEBENCH_DB or ~/.local/share/valvebench/local.db)");
    sub->add_flag("--no-store", no_store, "local: do not record the runs");
  };
  vb::experiment::TableOptions table;  // comparison tables: --metrics, --wide (docs/comparison.md)
  auto table_flags = [&](CLI::App* sub) {
    sub->add_option("--metrics", table.metrics, "table: these metrics (full names, as in --json)")->delimiter(',');
    sub->add_flag("--wide", table.wide, "table: every metric, not only the experiment kind's");
  };
  // Commands on stored runs: the server when one is given (and no --local), else the local store.
  auto stored_runs = [&](CLI::App* sub) {
    sub->add_flag("--local", local, "the local store, even if a server is configured");
    sub->add_option("--db", store_path, "local store (default $VALVEBENCH_DB or ~/.local/share/valvebench/local.db)");
  };
  auto* run = app.add_subcommand("run", "run an experiment spec (a single run or a batch)");
  run->add_option("spec", spec_path, "experiment spec (protobuf JSON)")->required();
  run->add_flag("--local", local, "run on the embedded emulator, no server");
  run->add_flag("--wait", wait, "remote: wait for the runs, progress on stderr, then the summary");
  run->add_option("--trace-csv", trace_csv, "local: write the recorded channels as CSV (batches: FILE-<n>.csv)");
  run->add_flag("--realtime", realtime, "local: pace the run to the wall clock and report loop jitter");
  common(run, true);
  local_store(run);
  table_flags(run);

  vb::benchctl::QueueOptions queue_opts;
  auto* queue = app.add_subcommand("queue", "runs queued and running (or matching --status/--batch/--tag), with ETA");
  queue->add_option("--status", queue_opts.status, "queued, running, done, failed, cancelled, interrupted");
  queue->add_option("--batch", queue_opts.batch, "runs of one batch");
  queue->add_option("--tag", queue_opts.tag, "runs with this tag");
  queue->add_option("--limit", queue_opts.limit, "at most this many (1-1000)")->check(CLI::Range(1, 1000));
  common(queue, true);
  stored_runs(queue);

  std::int64_t run_id = 0;
  auto* show = app.add_subcommand("show", "a run: status, times, metrics, history");
  show->add_option("run_id", run_id, "run id")->required();
  common(show, true);
  stored_runs(show);
  auto* watch = app.add_subcommand("watch", "follow a run until it ends (exit 1 if it did not succeed)");
  watch->add_option("run_id", run_id, "run id")->required();
  common(watch, false);
  stored_runs(watch);
  std::string reason;
  auto* cancel = app.add_subcommand("cancel", "cancel a queued or running run; reports the state it reached");
  cancel->add_option("run_id", run_id, "run id")->required();
  cancel->add_option("--reason", reason, "recorded with the run");
  common(cancel, false);
  stored_runs(cancel);
  vb::benchctl::ExportOptions export_opts;
  std::string export_csv_old;  // `--csv FILE`, the spelling before --trace-csv
  auto* exp = app.add_subcommand("export", "a stored run's trace as CSV, HDF5 or MATLAB .mat (units, spec, conditions)");
  exp->add_option("run_id", run_id, "run id")->required();
  exp->add_option("--csv", export_csv_old, "the trace as CSV on stdout")->expected(0, 1)->type_name("");
  exp->add_option("--trace-csv", export_opts.trace_csv, "the trace as CSV in FILE (as run --trace-csv)");
  exp->add_option("--hdf5", export_opts.hdf5, "HDF5 file: channels with units, spec and conditions (export/run_file.h)");
  exp->add_option("--mat", export_opts.mat, "MATLAB .mat file (level 5): struct vbrun (export/run_file.h)");
  common(exp, false);
  stored_runs(exp);
  auto* benches = app.add_subcommand("benches", "the server's benches and attached USB devices (--local: this machine's)");
  benches->add_flag("--local", local, "the embedded emulator and the USB devices this machine sees, no server");
  common(benches, false);

  std::string compare_input;
  std::int64_t batch = 0;
  std::vector<std::int64_t> run_ids;
  auto* compare = app.add_subcommand("compare", "compare runs: RMSE, effort and the other metrics side by side");
  compare->add_option("input", compare_input, "results JSON from `run --json`, or a spec with --local");
  compare->add_flag("--local", local, "SPEC: run its batch on the embedded emulator, then compare; --batch/--runs: "
                                      "the local store even if a server is configured");
  compare->add_option("--batch", batch, "compare the runs of this batch (the server's, or the local store's)");
  compare->add_option("--runs", run_ids, "compare these runs")->delimiter(',');
  common(compare, true);
  local_store(compare);
  table_flags(compare);

  // baseline, regress, nights (benchctl/regress_commands.cc).
  vb::benchctl::RegressCli regress_cli(&app, {&json, &server, &token, &tls_ca_file, &store_path});
  vb::benchctl::ReportCli report_cli(&app, {&json, &server, &token, &tls_ca_file, &store_path});
  // diagnose, identify, convert, import (benchctl/gap_commands.cc).
  vb::benchctl::GapCli gap_cli(&app, {&json, &server, &token, &tls_ca_file, &store_path});
  vb::benchctl::PruneCli prune_cli(&app, {&json, &server, &token, &tls_ca_file, &store_path});  // prune_command.cc
  vb::benchctl::DbCli db_cli(&app, {&json, &server, &token, &tls_ca_file, &store_path});  // db_commands.cc

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    if (rc != 0) SuggestOption(app, argc, argv);
    return rc == 0 ? 0 : kExitBadInput;
  }
  const vb::benchctl::Output out{json, csv};
  if (!tls_ca_file.empty() && !std::ifstream(tls_ca_file))
    return Fail(Status::NotFound("--tls-ca: cannot read '" + tls_ca_file + "' (a PEM file of the CA that signed "
                                 "the server's certificate)"));
  auto make_client = [&]() -> std::unique_ptr<vb::client::Client> {
    vb::client::ClientOptions opts;
    opts.address = server;
    opts.token = token;
    if (!tls_ca_file.empty()) {
      std::ifstream in(tls_ca_file);
      std::stringstream ss;
      ss << in.rdbuf();
      opts.tls_ca_pem = ss.str();
    }
    return std::make_unique<vb::client::Client>(opts);
  };
  auto need_server = [&]() {
    return Fail(Status::FailedPrecondition("no server given: --server ADDR or VALVEBENCH_SERVER"));
  };

  if (no_store) store_path.clear();
  if (regress_cli.parsed()) return regress_cli.Run(make_client);
  if (report_cli.parsed()) return report_cli.Run(make_client);
  if (gap_cli.parsed()) return gap_cli.Run(make_client);
  // One decision per invocation: the server if one is given and --local is not, else the local store.
  auto backend = [&](vb::benchctl::LocalUse use = {}) {
    return vb::benchctl::ChooseBackend(local ? "" : server, store_path, make_client, use);
  };
  if (prune_cli.parsed()) return prune_cli.Run();
  if (db_cli.parsed()) return db_cli.Run(make_client);
  if (run->parsed()) {
    if (!local && server.empty())
      return Fail(Status::FailedPrecondition(
          "no server given: use --local for the embedded emulator, or --server ADDR (or VALVEBENCH_SERVER)"));
    if (!local && (!trace_csv.empty() || realtime))
      return Fail(Status::InvalidArgument("--trace-csv and --realtime are local options; use `export` remotely"));
    return vb::benchctl::CmdRun(*backend({true, !trace_csv.empty()}), {spec_path, wait, trace_csv, realtime, table}, out);
  }
  if (compare->parsed()) {
    if (batch != 0 || !run_ids.empty()) {
      if (store_path.empty() && (local || server.empty()))
        return Fail(Status::InvalidArgument("--batch/--runs with --no-store: nothing is stored to compare"));
      return vb::benchctl::CmdCompareStored(*backend(), batch, run_ids, json, csv, table);
    }
    if (compare_input.empty())
      return Fail(Status::InvalidArgument("compare: give --batch B or --runs A,B,..., a results file, or --local SPEC"));
    if (local) return vb::benchctl::CmdCompareSpec(*backend({true, false}), compare_input, json, csv, table);
    return vb::benchctl::CmdCompare(compare_input, json, csv, table);
  }
  if (benches->parsed()) {
    if (!local && server.empty()) return need_server();
    return vb::benchctl::CmdBenches(*backend(), json);
  }
  if (queue->parsed()) return vb::benchctl::CmdQueue(*backend(), queue_opts, out);
  if (show->parsed()) return vb::benchctl::CmdShow(*backend(), run_id, out);
  if (watch->parsed()) return vb::benchctl::CmdWatch(*backend(), run_id, out);
  if (cancel->parsed()) return vb::benchctl::CmdCancel(*backend(), run_id, reason, out);
  if (exp->parsed()) {
    if (exp->count("--csv") > 0) {
      if (export_csv_old.empty() || export_csv_old == "-") {
        export_opts.csv_stdout = true;
      } else {  // the old spelling: still works, once more
        std::fprintf(stderr, "benchctl: note: `export --csv FILE` is now `export --trace-csv FILE` "
                             "(--csv alone: CSV on stdout, as everywhere)\n");
        export_opts.trace_csv = export_csv_old;
      }
    }
    return vb::benchctl::CmdExport(*backend(), run_id, export_opts, json);
  }
  return kExitBadInput;
}
