#include "benchctl/run_commands.h"

#include "common/csv.h"
#include "common/queue_estimate.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <memory>
#include <thread>

#include <unistd.h>

#include "benchctl/cli_common.h"
#include "client/run_file.h"
#include "client/trace_csv.h"
#include "export/run_file.h"

namespace vb::benchctl {
namespace {

double NowUnix() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
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

// A progress bar on stderr until the run ends (people at a terminal; `bar` false: silent).
Status WaitFor(Backend& backend, std::int64_t run_id, bool bar) {
  auto st = backend.Watch(run_id, [&](const RunView& ev) {
    if (bar) {
      const int filled = static_cast<int>(std::lround(30.0 * ev.progress));
      std::fprintf(stderr, "\rrun %lld [%-30s] %3.0f%% %-11s", static_cast<long long>(run_id),
                   std::string(static_cast<size_t>(std::clamp(filled, 0, 30)), '#').c_str(), 100.0 * ev.progress,
                   RunStatusName(ev.status));
      std::fflush(stderr);
    }
    return true;
  });
  if (bar) std::fprintf(stderr, "\n");
  return st;
}

// "m:ss" or "h:mm:ss".
std::string Duration(double s) {
  if (!std::isfinite(s) || s < 0.0) return "-";
  const long long t = std::llround(s);
  if (t >= 3600) return fmt::format("{}:{:02}:{:02}", t / 3600, (t / 60) % 60, t % 60);
  return fmt::format("{}:{:02}", t / 60, t % 60);
}

// A running run's remaining wall time, from its progress so far (by simulated time) and how long it has run.
std::string Eta(const RunView& r, double now) {
  if (r.status != RunStatus::kRunning || r.started_unix_s <= 0.0) return "-";
  const double left_s = RunningEta_s({r.id, r.status, r.priority, r.duration_s, r.progress, r.started_unix_s, "", ""}, now);
  return left_s < 0 ? "?" : Duration(left_s);
}

// The loop's own trace, every channel (run --trace-csv on a run executed here).
Status WriteTraceCsv(const experiment::Trace& trace, const std::string& path) {
  std::unique_ptr<FILE, int (*)(FILE*)> f(std::fopen(path.c_str(), "w"), &std::fclose);
  if (!f) return Status::Unavailable(path + ": cannot open for writing");
  const auto& names = experiment::Trace::ChannelNames();
  for (size_t c = 0; c < names.size(); ++c) std::fprintf(f.get(), "%s%s", c ? "," : "", names[c].c_str());
  std::fputc('\n', f.get());
  for (size_t k = 0; k < trace.size(); ++k) {
    // ref is NaN for a law without a reference: an empty field (common/csv.h AppendCsvNumber).
    std::fprintf(f.get(), "%.8f,%d,%.6g,%.9g,%.9g,%.9g,%s,%.9g,%.9g,%.12g,%.12g,%.0f\n", trace.t_s[k],
                 trace.gate[k], trace.v_coil_V[k], trace.i_A[k], trace.x_m[k], trace.v_mps[k], CsvNumber(trace.ref[k], 9).c_str(),
                 trace.x_avg_m[k], trace.flow_kg_per_s[k], trace.v2_int_V2s[k], trace.energy_int_J[k],
                 trace.switch_count[k]);
  }
  if (std::ferror(f.get())) return Status::DataLoss(path + ": write failed");
  return Status::Ok();
}

}  // namespace

int CmdRun(Backend& backend, const RunOptions& o, const Output& out) {
  auto spec = experiment::LoadSpecFile(o.spec_path);
  if (!spec.ok()) return Fail(spec.status());
  auto sub = backend.Submit(*spec, o.realtime);
  if (!sub.ok()) return Fail(sub.status().WithContext(o.spec_path));
  // A local service lives as long as this process: its runs are waited for, whatever --wait says.
  if (!backend.executes_here() && !o.wait) {  // queued on the server; watch, show or compare them later
    if (out.json) {
      std::cout << Json{{"batch_id", sub->batch_id}, {"run_ids", sub->run_ids}}.dump(2) << "\n";
    } else {
      std::printf("batch %lld:", static_cast<long long>(sub->batch_id));
      for (auto id : sub->run_ids) std::printf(" %lld", static_cast<long long>(id));
      std::printf("\n");
    }
    return kExitOk;
  }

  int code = kExitOk;
  std::vector<RunView> runs;
  std::vector<std::optional<experiment::Trace>> kept;  // the loop's whole traces, with --trace-csv
  for (size_t k = 0; k < sub->run_ids.size(); ++k) {
    const std::int64_t id = sub->run_ids[k];
    // The bar: for people; a local run that ran in this process before draws it only on a terminal, so its
    // output (stdout and stderr together, as scripts capture it) stays what it was.
    const bool bar = !out.json && !out.csv && (!backend.executes_here() || ::isatty(2) != 0);
    if (auto st = WaitFor(backend, id, bar); !st.ok())
      return Fail(st.WithContext("waiting for run " + std::to_string(id)));
    auto r = backend.GetRun(id);
    if (!r.ok()) return Fail(r.status());
    r->spec.reset();  // `show` has the spec and history; `run` lists what ran
    r->history.clear();
    if (!r->ok()) code = kExitRunFailed;
    runs.push_back(std::move(*r));
    kept.push_back(o.trace_csv.empty() ? std::nullopt : backend.KeptTrace(id));
  }
  if (!o.trace_csv.empty())
    for (size_t k = 0; k < runs.size(); ++k) {
      const std::string path = IndexedPath(o.trace_csv, k, runs.size());
      Status st;
      if (kept[k]) {  // the whole trace as the loop recorded it, every channel
        st = WriteTraceCsv(*kept[k], path);
      } else {  // what the service stored
        auto trace = backend.GetTrace(sub->run_ids[k]);
        if (!trace.ok()) return Fail(trace.status());
        std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(path.c_str(), "w"), &std::fclose);
        if (!f) return Fail(Status::Unavailable(path + ": cannot open for writing"));
        st = client::WriteTraceCsv(*trace, f.get(), path);  // the web's trace.csv rows
      }
      if (!st.ok()) return Fail(st);
    }
  const std::int64_t batch_id = sub->batch_id;
  if (!backend.keeps_runs())
    for (auto& r : runs) r.id = r.batch_id = 0;
  if (out.json) {
    Json all = Json::array();
    for (size_t k = 0; k < runs.size(); ++k) all.push_back(RunJson(runs[k]));
    std::cout << all.dump(2) << "\n";
  } else if (out.csv) {
    std::cout << RunsCsv(runs);
  } else {
    if (runs.size() == 1) {
      std::cout << RunText(runs[0], false);
    } else {  // a batch: one line per run, the metrics are in the comparison below (docs/comparison.md)
      for (const auto& r : runs) std::cout << RunLine(r);
      auto cmp = backend.Compare(batch_id, {});
      if (!cmp.ok()) return Fail(cmp.status());
      if (const std::string bad = experiment::CheckTableOptions(*cmp, o.table); !bad.empty())
        return Fail(Status::InvalidArgument(bad));
      std::cout << "\n" << experiment::ComparisonTable(*cmp, o.table);
    }
  }
  return code;
}

namespace {

// A queued or running run as `queue` lists it, with its place and ETA.
struct QueueRow {
  RunView run;
  int position = -1;   // -1: not in the queue view (a filtered list)
  double eta_s = -1.0;
};

void AddEstimate(Json* j, const QueueRow& q) {
  if (q.position < 0) return;
  (*j)["position"] = q.position;
  (*j)["eta_s"] = q.eta_s >= 0 ? Json(q.eta_s) : Json(nullptr);
}

}  // namespace

int CmdQueue(Backend& backend, const QueueOptions& o, const Output& out) {
  std::vector<QueueRow> rows;
  bool more = false;
  std::int64_t more_count = 0;  // how many more matched than are listed (0: unknown or none)
  int live = 0;
  const bool default_view = o.status.empty() && o.batch == 0 && o.tag.empty();
  if (default_view) {  // what is happening now (GetQueue): running runs first, then the queue in claim order
    auto q = backend.Queue();
    if (!q.ok()) return Fail(q.status());
    live = q->live_benches();
    for (const auto* list : {&q->running(), &q->queued()})
      for (const auto& x : *list) {
        if (static_cast<int>(rows.size()) >= o.limit) {
          more = true;
          ++more_count;
          continue;
        }
        rows.push_back({FromProto(x.run()), x.position(), x.eta_s()});
      }
  } else {
    RunFilter f{std::nullopt, o.batch, o.tag, o.limit};
    if (!o.status.empty()) {
      auto s = ParseRunStatus(o.status);
      if (!s.ok()) return Fail(s.status().WithContext("--status"));
      f.status = *s;
    }
    std::int64_t total = 0;
    auto page = backend.ListRuns(f, &more, &total);
    if (!page.ok()) return Fail(page.status());
    if (more && total > static_cast<std::int64_t>(page->size())) more_count = total - static_cast<std::int64_t>(page->size());
    for (auto& r : *page) rows.push_back({std::move(r), -1, -1.0});
  }
  const bool any_queued =
      std::any_of(rows.begin(), rows.end(), [](const QueueRow& r) { return r.run.status == RunStatus::kQueued; });
  if (out.json) {
    Json a = Json::array();
    for (const auto& q : rows) {
      Json j = RunJson(q.run);
      AddEstimate(&j, q);
      a.push_back(std::move(j));
    }
    Json all{{"where", backend.Where()}, {"runs", a}, {"more", more}};
    if (default_view && any_queued) all["live_benches"] = live;
    std::cout << all.dump(2) << "\n";
    return kExitOk;
  }
  if (out.csv) {
    std::vector<RunView> runs;
    for (const auto& q : rows) runs.push_back(q.run);
    std::cout << RunsCsv(runs);
    return kExitOk;
  }
  if (rows.empty()) {
    std::printf("%s on %s\n", default_view ? "no runs queued or running" : "no runs match", backend.Where().c_str());
    return kExitOk;
  }
  std::map<RunStatus, int> count;
  for (const auto& q : rows) ++count[q.run.status];
  std::string counts;
  for (const auto& [status, n] : count) counts += fmt::format("{}{} {}", counts.empty() ? "" : ", ", n, RunStatusName(status));
  // A list cut at --limit says how many matched in all ("100 of 177 runs"), not only how many it shows.
  const std::string how_many = more && more_count > 0
                                   ? fmt::format("{} of {} runs", rows.size(), rows.size() + more_count)
                                   : more ? fmt::format("the first {} runs", rows.size())
                                          : fmt::format("{} runs", rows.size());
  std::printf("%s on %s: %s%s%s\n", how_many.c_str(), backend.Where().c_str(), more ? "shown: " : "", counts.c_str(),
              count.count(RunStatus::kRunning) ? " (ETA: wall time left, from progress so far)" : "");
  if (default_view && any_queued)
    std::printf("queued: position in claim order, ETA from the runs' durations on the live benches that can run "
                "each (%d live)\n", live);
  const bool lab = std::any_of(rows.begin(), rows.end(), [](const QueueRow& q) { return !q.run.host.empty(); });
  std::printf("%6s %6s  %-11s %8s %5s %8s  %-16s %s%-20s %-10s %s\n", "id", "batch", "status", "progress", "pos", "ETA",
              "bench", lab ? "host         " : "", "controller", "submitter", "name");
  const double now = NowUnix();
  for (const auto& q : rows) {
    const RunView& r = q.run;
    std::string pos = "-", eta = Eta(r, now);
    if (q.position > 0) pos = std::to_string(q.position);
    if (q.position >= 0) eta = q.eta_s >= 0 ? Duration(q.eta_s) : "?";
    std::printf("%6lld %6lld  %-11s %6.0f %% %5s %8s  %-16s %s%-20s %-10s %s\n", static_cast<long long>(r.id),
                static_cast<long long>(r.batch_id), RunStatusName(r.status), 100.0 * r.progress, pos.c_str(),
                eta.c_str(), r.bench.empty() ? "any" : r.bench.c_str(),
                lab ? fmt::format("{:<12.12} ", r.host).c_str() : "", r.controller.c_str(), r.submitter.c_str(),
                r.key.DisplayName().c_str());
  }
  if (more) {
    if (more_count > 0)
      std::fprintf(stderr, "(%lld more; --limit)\n", static_cast<long long>(more_count));
    else
      std::fprintf(stderr, "(cut at %d; --limit for more)\n", o.limit);
  }
  return kExitOk;
}

int CmdShow(Backend& backend, std::int64_t run_id, const Output& out) {
  auto r = backend.GetRun(run_id);
  if (!r.ok()) return Fail(r.status());
  if (out.json) {
    std::cout << RunJson(*r).dump(2) << "\n";
  } else if (out.csv) {
    std::cout << RunsCsv({*r});
  } else {
    std::cout << RunText(*r, true);
  }
  return kExitOk;
}

int CmdWatch(Backend& backend, std::int64_t run_id, const Output& out) {
  Status st;
  if (out.json) {  // one JSON object per line and event: a script follows the run as it goes
    st = backend.Watch(run_id, [&](const RunView& ev) {
      std::cout << Json{{"id", run_id}, {"status", RunStatusName(ev.status)}, {"progress", ev.progress},
                        {"reason", ev.reason}}.dump()
                << "\n" << std::flush;
      return true;
    });
  } else {
    st = WaitFor(backend, run_id, true);
  }
  if (!st.ok()) return Fail(st);
  auto r = backend.GetRun(run_id);
  if (!r.ok()) return Fail(r.status());
  if (!out.json) std::cout << RunText(*r, false);
  return r->ok() ? kExitOk : kExitRunFailed;
}

int CmdCancel(Backend& backend, std::int64_t run_id, const std::string& reason, const Output& out,
              double cancel_wait_s) {
  auto r = backend.Cancel(run_id, reason);
  if (!r.ok()) return Fail(r.status());
  // A running run stops at its loop's next check; report the state it reached, not the request.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(cancel_wait_s);
  while (!r->ended() && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    auto now = backend.GetRun(run_id);
    if (!now.ok()) return Fail(now.status());
    r = std::move(now);
  }
  if (out.json) {
    Json j = RunJson(*r);
    j["cancel"] = r->status == RunStatus::kCancelled ? "done" : r->ended() ? "too late" : "pending";
    std::cout << j.dump(2) << "\n";
    return kExitOk;
  }
  if (r->ended()) {
    if (r->status != RunStatus::kCancelled)
      std::printf("run %lld had already ended (%s) when the cancel arrived\n", static_cast<long long>(run_id),
                  RunStatusName(r->status));
    std::cout << RunText(*r, false);
  } else {
    std::printf("run %lld: cancel requested, still %s at %.0f %% after %.0f s; it stops at its loop's next check "
                "(benchctl watch %lld follows it)\n",
                static_cast<long long>(run_id), RunStatusName(r->status), 100.0 * r->progress, cancel_wait_s,
                static_cast<long long>(run_id));
  }
  return kExitOk;
}

int CmdExport(Backend& backend, std::int64_t run_id, const ExportOptions& o, bool json) {
  if (json && o.csv_stdout) return Fail(Status::InvalidArgument("export: --json and --csv both want stdout; pick one"));
  if (!o.csv_stdout && o.trace_csv.empty() && o.hdf5.empty() && o.mat.empty())
    return Fail(Status::InvalidArgument("export: give --csv (stdout), --trace-csv FILE, --hdf5 FILE or --mat FILE"));
  auto run = backend.ApiRun(run_id);
  if (!run.ok()) return Fail(run.status());
  auto trace = backend.GetTrace(run_id);
  if (!trace.ok()) return Fail(trace.status());
  const std::size_t n_samples = trace->columns.empty() ? 0 : trace->columns.begin()->second.size();
  const std::size_t n_channels = trace->channels.size();
  if (o.csv_stdout)
    if (auto st = client::WriteTraceCsv(*trace, stdout, "stdout"); !st.ok()) return Fail(st);
  if (!o.trace_csv.empty()) {
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(o.trace_csv.c_str(), "w"), &std::fclose);
    if (!f) return Fail(Status::Unavailable(o.trace_csv + ": cannot open for writing"));
    if (auto st = client::WriteTraceCsv(*trace, f.get(), o.trace_csv); !st.ok()) return Fail(st);
  }
  auto written = [&]() {
    if (!json) {
      // Say what was written (issue 37: export printed nothing); on stderr when the trace itself is on stdout.
      std::FILE* to = o.csv_stdout ? stderr : stdout;
      for (const auto& [format, path] : {std::pair<const char*, const std::string*>{"trace CSV", &o.trace_csv},
                                         {"HDF5", &o.hdf5},
                                         {"MAT", &o.mat}})
        if (!path->empty())
          std::fprintf(to, "run %lld: %s written to %s (%zu samples, %zu channels)\n", static_cast<long long>(run_id),
                       format, path->c_str(), n_samples, n_channels);
      return kExitOk;
    }
    Json files = Json::array();
    if (!o.trace_csv.empty()) files.push_back({{"format", "csv"}, {"path", o.trace_csv}});
    if (!o.hdf5.empty()) files.push_back({{"format", "hdf5"}, {"path", o.hdf5}});
    if (!o.mat.empty()) files.push_back({{"format", "mat"}, {"path", o.mat}});
    std::cout << Json{{"id", run_id}, {"files", files}}.dump(2) << "\n";
    return kExitOk;
  };
  if (o.hdf5.empty() && o.mat.empty()) return written();

  // The file the web's trace.h5/.mat serves too (client/run_file.h).
  const exportfile::RunFile f = client::RunFileOf(*run, std::move(*trace));
  if (!o.hdf5.empty())
    if (auto st = exportfile::WriteHdf5(f, o.hdf5); !st.ok()) return Fail(st);
  if (!o.mat.empty())
    if (auto st = exportfile::WriteMat(f, o.mat); !st.ok()) return Fail(st);
  return written();
}

}  // namespace vb::benchctl
