// BenchService::DiagnoseRuns: the gap diagnosis of stored runs on the server (docs/gap.md, "Stored runs"), the
// same dataset (gap::DatasetOfStoredRuns) and the same diagnosis and report as `benchctl diagnose --runs`.
#include <google/protobuf/util/json_util.h>

#include <map>

#include "common/trace_columns.h"
#include "gap/diagnose.h"
#include "gap/improved_model.h"
#include "gap/stored_runs.h"
#include "gap/suggest.h"
#include "experiment/spec.h"
#include "model/params.h"
#include "service/grpc_status.h"
#include "service/service.h"
#include "service/stored_run.h"

namespace vb::server {

namespace v1 = valvebench::v1;

namespace {

constexpr int kMaxRuns = 100;


}  // namespace

// One stored run, from the store: its conditions from its spec, its gate and current from its trace.
StatusOr<gap::StoredRun> LoadStoredRun(db::Store* store, std::int64_t id) {
  const std::string where = "run " + std::to_string(id);
  auto run = store->GetRun(id);
  if (!run.ok()) return run.status();
  if (run->status != db::RunStatus::kDone) return Status::FailedPrecondition(where + ": not done");
  v1::ExperimentSpec spec;
  if (!google::protobuf::util::JsonStringToMessage(run->spec_json, &spec).ok())
    return Status::DataLoss(where + ": its stored spec does not parse");
  gap::StoredRun s = gap::StoredRunOf(id, run->key, spec, run->started_unix_s,
                                      std::isfinite(run->t_start_s) ? std::optional<double>(run->t_start_s)
                                                                    : std::nullopt,
                                      run->split);
  TraceDecoder decoder({"gate", "i_A"});  // the one decoder (common/trace_columns.h), the two channels kept
  VB_RETURN_IF_ERROR(store->ForEachTraceChunk(id, [&](const db::TraceChunk& c, std::int64_t total) {
    ChunkView view;
    view.index = c.index;
    view.t0_s = c.t0_s;
    view.sample_period_s = c.sample_period_s;
    view.samples = c.samples;
    view.total_samples = total;
    view.channels = &c.channels;
    view.data = c.data.data();
    return decoder.Add(view).WithContext(where);
  }));
  TraceColumns trace = decoder.Take();
  auto* gate = trace.Find("gate");
  auto* current = trace.Find("i_A");
  if (gate == nullptr || current == nullptr)
    return Status::InvalidArgument(where + ": the trace has no gate and i_A channels");
  s.sample_period_s = trace.sample_period_s;
  s.gate = std::move(trace.columns["gate"]);
  s.i_A = std::move(trace.columns["i_A"]);
  return s;
}

grpc::Status BenchServiceImpl::DiagnoseRuns(grpc::ServerContext* ctx, const v1::DiagnoseRunsRequest* req,
                                            v1::DiagnoseRunsResponse* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  if (req->run_ids_size() == 0) return ToGrpcStatus(Status::InvalidArgument("run_ids: at least one run is needed"));
  if (req->run_ids_size() > kMaxRuns)
    return ToGrpcStatus(Status::InvalidArgument("run_ids: " + std::to_string(req->run_ids_size()) +
                                                " runs, at most " + std::to_string(kMaxRuns)));
  std::map<std::int64_t, int> seen;
  for (int k = 0; k < req->run_ids_size(); ++k)
    if (auto [it, fresh] = seen.emplace(req->run_ids(k), k); !fresh)
      return ToGrpcStatus(Status::InvalidArgument("run_ids[" + std::to_string(k) + "]: run " +
                                                  std::to_string(req->run_ids(k)) + " is also run_ids[" +
                                                  std::to_string(it->second) + "]"));
  std::vector<gap::StoredRun> stored;
  {
    auto store = pool_->Acquire();
    if (!store.ok()) return ToGrpcStatus(store.status());
    for (int k = 0; k < req->run_ids_size(); ++k) {
      auto s = LoadStoredRun(store->get(), req->run_ids(k));
      if (!s.ok()) return ToGrpcStatus(s.status().WithContext("run_ids[" + std::to_string(k) + "]"));
      stored.push_back(std::move(*s));
    }
  }
  auto ds = gap::DatasetOfStoredRuns(std::move(stored));
  if (!ds.ok()) return ToGrpcStatus(ds.status());
  // The nominal model: a model file's spec (its values and identified driver, as `benchctl diagnose --model
  // FILE` reads one), a preset, or the runs' own.
  if (req->has_model_spec() && !req->model().empty())
    return ToGrpcStatus(Status::InvalidArgument("model: give a preset or model_spec, not both"));
  valvebench::v1::ModelSpec nominal_spec;
  std::string model_name;
  model::PlantParams nominal;
  if (req->has_model_spec()) {
    nominal_spec = req->model_spec();
    auto plant = experiment::BuildPlant(nominal_spec);
    if (!plant.ok()) return ToGrpcStatus(plant.status().WithContext("model_spec"));
    nominal = *plant;
    if (nominal_spec.has_identified_driver()) {
      auto driver = experiment::BuildDriver(nominal_spec.identified_driver());
      if (!driver.ok()) return ToGrpcStatus(driver.status().WithContext("model_spec.identified_driver"));
      ds->driver = *driver;  // the model's identified driver replaces the runs' declared one (as the CLI does)
    }
    model_name = nominal_spec.preset().empty() ? std::string("model file") : nominal_spec.preset() + " (model file)";
  } else {
    model_name = req->model().empty() ? ds->model : req->model();
    auto preset = model::Preset(model_name);
    if (!preset.ok()) return ToGrpcStatus(Status::InvalidArgument("model: unknown preset '" + model_name + "'"));
    nominal = *preset;
    nominal_spec.set_preset(model_name);
  }
  gap::DiagnoseOptions options;
  options.model_name = model_name;
  auto d = gap::Diagnose(*ds, nominal, options);
  if (!d.ok()) return ToGrpcStatus(d.status().WithContext("stored runs"));
  resp->set_report(gap::DiagnosisReport(*d));
  resp->set_report_json(gap::DiagnosisJson(*d));
  if (req->suggest()) {
    auto s = gap::SuggestNextRuns(*ds, nominal, *d);
    if (!s.ok()) return ToGrpcStatus(s.status().WithContext("suggest"));
    resp->set_suggestion_report(gap::SuggestionReport(*s));
    resp->set_suggestion_json(gap::SuggestionJson(*s));
    if (!s->runs.empty())
      resp->set_suggestion_spec_json(gap::SuggestionSpecJson(
          *s, "next-experiment", nominal_spec.preset().empty() ? model::kDefaultPreset : nominal_spec.preset()));
  }
  // The improved model, built as `benchctl diagnose --model-out` builds it (gap/improved_model.h); "" when no
  // effect was attributed (verdict none or unknown: api.proto).
  std::string runs;
  for (int k = 0; k < req->run_ids_size(); ++k) {
    if (k > 0) runs += ',';
    runs += std::to_string(req->run_ids(k));
  }
  auto improved = gap::ImprovedModel(*d, nominal_spec, ds->driver, "the server's DiagnoseRuns on runs " + runs);
  if (d->chosen >= 0 && improved.ok()) resp->set_improved_model_json(gap::ModelSpecJson(*improved));
  return grpc::Status::OK;
}

}  // namespace vb::server
