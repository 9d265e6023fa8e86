// BenchService::ImportRuns: measured runs stored as finished runs, for the gap diagnosis (docs/server.md,
// "Imported runs").
//
// Each run becomes a run of batch "import:<dataset>" with an ExperimentSpec that records what a run has
// (name, conditions, duration, the nominal model), its split and start time as the run's own fields (store
// columns, Run.split and Run.t_start_s), and tags for people and filters ("imported", "dataset:<name>", and
// "split:<split>", "t_start_s:<t>" which benchctl diagnose still reads until it takes the fields); its bench
// kind "imported" matches no bench, so no worker ever claims it.
// The whole request is validated before anything is stored: a bad run stores nothing.
#include <google/protobuf/util/json_util.h>

#include <cmath>
#include <mutex>

#include "common/format.h"
#include "model/params.h"
#include "server/grpc_status.h"
#include "server/service.h"

namespace vb::server {

namespace v1 = valvebench::v1;

namespace {

constexpr const char* kImportedKind = "imported";
constexpr std::size_t kChunkSamples = 65536;

Status ValidateRun(const v1::ImportedRun& r, const std::string& where) {
  if (r.id().empty()) return Status::InvalidArgument(where + ".id: must not be empty");
  if (!(r.supply_v() > 0.0) || !std::isfinite(r.supply_v()))
    return Status::InvalidArgument(where + ".supply_V: must be > 0, got " + FormatNumber(r.supply_v()));
  if (!(r.supply_pressure_pa() >= 0.0) || !std::isfinite(r.supply_pressure_pa()))
    return Status::InvalidArgument(where + ".supply_pressure_Pa: must be >= 0, got " + FormatNumber(r.supply_pressure_pa()));
  if (!(r.t_start_s() >= 0.0) || !std::isfinite(r.t_start_s()))
    return Status::InvalidArgument(where + ".t_start_s: must be >= 0, got " + FormatNumber(r.t_start_s()));
  if (!(r.sample_period_s() > 0.0) || !std::isfinite(r.sample_period_s()))
    return Status::InvalidArgument(where + ".sample_period_s: must be > 0, got " + FormatNumber(r.sample_period_s()));
  if (!r.split().empty() && r.split() != "fit" && r.split() != "holdout")
    return Status::InvalidArgument(where + ".split: must be \"fit\", \"holdout\" or empty, got \"" + r.split() + "\"");
  const int n = r.gate_size();
  if (n < 2) return Status::InvalidArgument(where + ".gate: at least 2 samples are needed, got " + std::to_string(n));
  if (r.i_a_size() != n)
    return Status::InvalidArgument(where + ".i_A: " + std::to_string(r.i_a_size()) + " samples for " +
                                   std::to_string(n) + " gate samples");
  for (const auto* col : {&r.x_m(), &r.v_coil_v()})
    if (col->size() != 0 && col->size() != n)
      return Status::InvalidArgument(where + (col == &r.x_m() ? ".x_m: " : ".v_coil_V: ") +
                                     std::to_string(col->size()) + " samples for " + std::to_string(n));
  for (int k = 0; k < n; ++k) {
    if (r.gate(k) != 0 && r.gate(k) != 1)
      return Status::InvalidArgument(where + ".gate[" + std::to_string(k) + "]: must be 0 or 1, got " +
                                     std::to_string(r.gate(k)));
    if (!std::isfinite(r.i_a(k)))
      return Status::InvalidArgument(where + ".i_A[" + std::to_string(k) + "]: not a finite number");
  }
  return Status::Ok();
}

std::mutex import_mu;  // one import at a time: the claim below must find this import's runs

}  // namespace

grpc::Status BenchServiceImpl::ImportRuns(grpc::ServerContext* ctx, const v1::ImportRunsRequest* req,
                                          v1::SubmitRunResponse* resp) {
  Principal who;
  if (auto st = Authorize(ctx, Role::kOperator, &who); !st.ok()) return st;
  if (req->dataset().empty()) return ToGrpcStatus(Status::InvalidArgument("dataset: must name the dataset"));
  if (req->runs_size() == 0) return ToGrpcStatus(Status::InvalidArgument("runs: at least one run is needed"));
  const std::string model = req->model().empty() ? "taghizadeh2009" : req->model();
  if (!model::Preset(model).ok())
    return ToGrpcStatus(Status::InvalidArgument("model: unknown model '" + model + "'"));
  if (static_cast<std::uint32_t>(req->runs_size()) > settings_->limits.max_runs_per_submission())
    return ToGrpcStatus(Status::ResourceExhausted("runs: " + std::to_string(req->runs_size()) +
                                                  " runs exceed the server limit of " +
                                                  std::to_string(settings_->limits.max_runs_per_submission())));
  std::vector<db::RunRecord> records;
  for (int k = 0; k < req->runs_size(); ++k) {
    const auto& r = req->runs(k);
    const std::string where = "runs[" + std::to_string(k) + "]";
    if (auto st = ValidateRun(r, where); !st.ok()) return ToGrpcStatus(st);
    if (k > 0 && r.t_start_s() < req->runs(k - 1).t_start_s())
      return ToGrpcStatus(Status::InvalidArgument(where + ".t_start_s: runs must be in time order"));
    v1::ExperimentSpec spec;
    spec.set_name(r.id());
    spec.set_description(req->description());
    spec.mutable_bench()->set_kind(kImportedKind);
    spec.mutable_bench()->mutable_model()->set_preset(model);
    spec.mutable_conditions()->set_supply_v(r.supply_v());
    spec.mutable_conditions()->set_supply_pressure_pa(r.supply_pressure_pa());
    spec.set_duration_s(static_cast<double>(r.gate_size() - 1) * r.sample_period_s());
    spec.set_never_requeue(true);
    for (const std::string& tag : {std::string("imported"), "dataset:" + req->dataset(),
                                   "split:" + (r.split().empty() ? std::string("none") : r.split()),
                                   "t_start_s:" + FormatNumber(r.t_start_s())})
      spec.add_tags(tag);
    db::RunRecord rec;
    rec.key = NamedRun(r.id());
    rec.split = r.split();
    rec.t_start_s = r.t_start_s();
    rec.controller = "imported";
    rec.bench_kind = kImportedKind;
    rec.requeue_on_interrupt = false;
    rec.tags.assign(spec.tags().begin(), spec.tags().end());
    google::protobuf::util::JsonPrintOptions o;
    o.preserve_proto_field_names = true;
    (void)google::protobuf::util::MessageToJsonString(spec, &rec.spec_json, o);
    records.push_back(std::move(rec));
  }

  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  std::lock_guard<std::mutex> lock(import_mu);
  std::vector<std::int64_t> ids;
  auto batch = (*store)->SubmitBatch(who.user, "import:" + req->dataset(), "{}", records, &ids);
  if (!batch.ok()) return ToGrpcStatus(batch.status());
  for (int k = 0; k < req->runs_size(); ++k) {
    const auto& r = req->runs(k);
    auto claimed = (*store)->ClaimNext(db::BenchClaim(kImportedKind, "import"));
    if (!claimed.ok()) return ToGrpcStatus(claimed.status());
    if (!claimed->has_value() || (*claimed)->id != ids[static_cast<std::size_t>(k)])
      return ToGrpcStatus(Status::Internal("import: run " + std::to_string(ids[static_cast<std::size_t>(k)]) +
                                           " was not next in the queue"));
    const std::size_t n = static_cast<std::size_t>(r.gate_size());
    std::vector<std::string> channels = {"t_s", "gate", "i_A"};
    if (r.x_m_size() > 0) channels.push_back("x_m");
    if (r.v_coil_v_size() > 0) channels.push_back("v_coil_V");
    Status st = Status::Ok();
    for (std::size_t from = 0, index = 0; from < n && st.ok(); from += kChunkSamples, ++index) {
      const std::size_t m = std::min(kChunkSamples, n - from);
      db::TraceChunk c;
      c.index = static_cast<std::int32_t>(index);
      c.t0_s = static_cast<double>(from) * r.sample_period_s();
      c.sample_period_s = r.sample_period_s();
      c.samples = static_cast<std::int32_t>(m);
      c.channels = channels;
      c.data.reserve(channels.size() * m);
      for (std::size_t j = 0; j < m; ++j) c.data.push_back(static_cast<double>(from + j) * r.sample_period_s());
      for (std::size_t j = 0; j < m; ++j) c.data.push_back(r.gate(static_cast<int>(from + j)));
      for (std::size_t j = 0; j < m; ++j) c.data.push_back(r.i_a(static_cast<int>(from + j)));
      if (r.x_m_size() > 0)
        for (std::size_t j = 0; j < m; ++j) c.data.push_back(r.x_m(static_cast<int>(from + j)));
      if (r.v_coil_v_size() > 0)
        for (std::size_t j = 0; j < m; ++j) c.data.push_back(r.v_coil_v(static_cast<int>(from + j)));
      st = (*store)->AppendTraceChunk(db::LeaseOf(**claimed), c);
    }
    if (st.ok()) st = (*store)->Finish(db::LeaseOf(**claimed), db::RunStatus::kDone, "imported from " + req->dataset(), {});
    if (!st.ok()) {
      (void)(*store)->Finish(db::LeaseOf(**claimed), db::RunStatus::kFailed, "import failed: " + st.message(), {});
      return ToGrpcStatus(st.WithContext("runs[" + std::to_string(k) + "]"));
    }
    resp->add_run_ids((*claimed)->id);
  }
  resp->set_batch_id(*batch);
  return grpc::Status::OK;
}

}  // namespace vb::server
