#include "benchctl/local_run.h"

#include <cstdio>
#include <memory>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>

#include "db/store.h"
#include "db/trace_writer.h"
#include "hw/emulated_bench.h"

namespace vb::benchctl {

std::string DefaultLocalStorePath() {
  if (const char* p = std::getenv("VALVEBENCH_DB"); p != nullptr && *p != '\0') return p;
  if (const char* home = std::getenv("HOME"); home != nullptr && *home != '\0')
    return std::string(home) + "/.local/share/valvebench/local.db";
  return "valvebench-local.db";
}

namespace {

constexpr const char* kLocalBenchKind = "local";
constexpr const char* kLocalBenchName = "local-emulator";

std::string RunName(const experiment::ExperimentSpec& spec) {
  std::string name = spec.name();
  for (const auto& tag : spec.tags())
    if (tag.rfind("sweep:", 0) == 0 || tag.rfind("repeat:", 0) == 0) name += " " + tag;
  return name;
}

LocalRunResult Execute(const experiment::Experiment& e, bool keep_traces) {
  hw::EmulatedBench bench(experiment::EmulatedBenchFor(e));
  LocalRunResult r;
  r.name = RunName(e.spec);
  r.tags.assign(e.spec.tags().begin(), e.spec.tags().end());
  r.controller = std::string(e.controller->name());
  r.summary = experiment::Runner::Run(e, bench, &r.trace);
  if (!keep_traces) r.trace = experiment::Trace{};
  return r;
}

}  // namespace

StatusOr<std::vector<LocalRunResult>> RunLocal(const experiment::ExperimentSpec& spec, bool realtime, bool keep_traces,
                                               const std::string& store_path) {
  auto points = experiment::ExpandSweep(spec);
  if (!points.ok()) return points.status();
  return RunLocalPoints(*points, spec.name(), experiment::SpecToJson(spec, false), realtime, keep_traces, store_path);
}

StatusOr<std::vector<LocalRunResult>> RunLocalPoints(const std::vector<experiment::ExperimentSpec>& points,
                                                     const std::string& batch_name, const std::string& batch_json,
                                                     bool realtime, bool keep_traces, const std::string& store_path) {
  // Build everything first: a bad point fails the whole submission before anything runs or is stored.
  std::vector<experiment::Experiment> exps;
  for (size_t k = 0; k < points.size(); ++k) {
    auto e = experiment::BuildExperiment(points[k]);
    if (!e.ok()) return points.size() > 1 ? e.status().WithContext("run " + std::to_string(k)) : e.status();
    if (realtime) e->run.realtime = true;
    exps.push_back(std::move(e.value()));
  }
  std::vector<LocalRunResult> out;
  if (store_path.empty()) {
    for (const auto& e : exps) out.push_back(Execute(e, keep_traces));
    return out;
  }

  if (const auto parent = std::filesystem::path(store_path).parent_path(); !parent.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(parent, ec);
  }
  auto store = db::Store::Open(store_path);
  if (!store.ok()) return store.status().WithContext("local store " + store_path);
  const char* user = std::getenv("USER");
  const std::string submitter = user != nullptr && *user != '\0' ? user : "local";
  std::vector<db::RunRecord> records;
  for (const auto& e : exps) {
    db::RunRecord rec;
    rec.name = RunName(e.spec);
    rec.controller = std::string(e.controller->name());
    rec.bench_kind = kLocalBenchKind;
    rec.spec_json = experiment::SpecToJson(e.spec, false);
    rec.submitter = submitter;
    rec.priority = e.spec.priority();
    rec.tags.assign(e.spec.tags().begin(), e.spec.tags().end());
    records.push_back(std::move(rec));
  }
  std::vector<std::int64_t> ids;
  auto batch = (*store)->SubmitBatch(submitter, batch_name, batch_json, std::move(records), &ids);
  if (!batch.ok()) return batch.status().WithContext("local store " + store_path);
  std::map<std::int64_t, size_t> index_of;
  for (size_t k = 0; k < ids.size(); ++k) index_of[ids[k]] = k;
  for (size_t n = 0; n < exps.size(); ++n) {
    auto claimed = (*store)->ClaimNext(kLocalBenchKind, kLocalBenchName);
    if (!claimed.ok()) return claimed.status().WithContext("local store " + store_path);
    if (!claimed->has_value()) return Status::Internal("local store: a submitted run was not there to claim");
    const auto it = index_of.find((*claimed)->id);
    if (it == index_of.end()) {
      // A run left queued by an earlier, interrupted local invocation: mark it so and move on.
      (void)(*store)->Finish((*claimed)->id, db::RunStatus::kCancelled, "left over from an interrupted local run", {});
      --n;
      continue;
    }
    LocalRunResult r = Execute(exps[it->second], true);
    r.run_id = (*claimed)->id;
    r.batch_id = *batch;
    Status st = db::AppendRecordedTrace(store->get(), r.run_id, r.trace);
    std::vector<db::Metric> metrics;
    for (const auto& [name, value] : experiment::MetricList(r.summary.metrics))
      if (std::isfinite(value)) metrics.push_back({name, value});
    db::RunStatus status = r.summary.ok() ? db::RunStatus::kDone
                           : r.summary.termination == experiment::RunSummary::Termination::kCancelled
                               ? db::RunStatus::kCancelled
                               : db::RunStatus::kFailed;
    std::string reason = r.summary.message;
    if (!st.ok() && status == db::RunStatus::kDone) {
      status = db::RunStatus::kFailed;
      reason = "storing the trace failed: " + st.message();
    }
    VB_RETURN_IF_ERROR((*store)->Finish(r.run_id, status, reason, metrics).WithContext("local store " + store_path));
    if (!keep_traces) r.trace = experiment::Trace{};
    out.push_back(std::move(r));
  }
  return out;
}

Status WriteTraceCsv(const experiment::Trace& trace, const std::string& path) {
  std::unique_ptr<FILE, int (*)(FILE*)> f(std::fopen(path.c_str(), "w"), &std::fclose);
  if (!f) return Status::Unavailable(path + ": cannot open for writing");
  const auto& names = experiment::Trace::ChannelNames();
  for (size_t c = 0; c < names.size(); ++c) std::fprintf(f.get(), "%s%s", c ? "," : "", names[c].c_str());
  std::fputc('\n', f.get());
  for (size_t k = 0; k < trace.size(); ++k) {
    std::fprintf(f.get(), "%.8f,%d,%.6g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.12g,%.12g,%.0f\n", trace.t_s[k],
                 trace.gate[k], trace.v_coil_V[k], trace.i_A[k], trace.x_m[k], trace.v_mps[k], trace.ref[k],
                 trace.x_avg_m[k], trace.flow_kg_per_s[k], trace.v2_int_V2s[k], trace.energy_int_J[k],
                 trace.switch_count[k]);
  }
  if (std::ferror(f.get())) return Status::DataLoss(path + ": write failed");
  return Status::Ok();
}

}  // namespace vb::benchctl
