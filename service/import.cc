// BenchService::ImportRuns: measured runs stored as finished runs, for the gap diagnosis (docs/server.md,
// "Imported runs").
//
// Each run becomes a run of batch "import:<dataset>" with an ExperimentSpec that records what a run has
// (name, conditions, duration, the nominal model), its split and start time as the run's own fields (store
// columns, Run.split and Run.t_start_s), and tags for people and filters ("imported", "dataset:<name>", and
// "split:<split>", "t_start_s:<t>" which benchctl diagnose still reads until it takes the fields); its bench
// kind "imported" matches no bench, so no worker ever claims it.
// ImportRuns validates the whole request before anything is stored: a bad run stores nothing. ImportRunsStream
// validates the header (every run's metadata) first, then each part of samples as it arrives; a bad sample
// fails that run and the ones after it with the reason (the runs before it stay imported).
#include <google/protobuf/util/json_util.h>

#include <cmath>
#include <map>
#include <memory>
#include <mutex>

#include "common/format.h"
#include "common/split.h"
#include "experiment/bounds.h"
#include "model/params.h"
#include "service/grpc_status.h"
#include "service/service.h"

namespace vb::server {

namespace v1 = valvebench::v1;

namespace {

constexpr const char* kImportedKind = "imported";
constexpr std::size_t kChunkSamples = 65536;

// Physical bounds of what a measured run carries (docs/server.md, "Imported runs"): the conditions use the
// spec's own table (experiment/bounds.h); the samples are bounded by what any solenoid bench measures.
constexpr double kMinSamplePeriod_s = 1e-9, kMaxSamplePeriod_s = 10.0;
constexpr double kMaxStart_s = 1e9;         // 31 years of bench power-on time
constexpr double kMaxAbsCurrent_A = 1e3;
constexpr double kMaxAbsPosition_m = 1.0;
constexpr double kMaxAbsVoltage_V = 1e4;
constexpr std::int64_t kMaxSamplesPerRun = std::int64_t{1} << 31;

Status InRange(const std::string& field, double v, double lo, double hi, const char* unit) {
  if (std::isfinite(v) && v >= lo && v <= hi) return Status::Ok();
  return Status::InvalidArgument(field + ": must be in [" + FormatNumber(lo) + ", " + FormatNumber(hi) + "] " + unit +
                                 ", got " + FormatNumber(v));
}

// A condition a spec also carries, within the spec's bounds (experiment/bounds.h), named as the import's field.
Status SpecBound(const std::string& field, std::string_view spec_field, double v) {
  const experiment::FieldBound* b = experiment::FindSpecBound(spec_field);
  if (b == nullptr) return Status::Ok();
  return InRange(field, v, b->min, b->max, std::string(b->unit).c_str());
}

// A run's metadata; `samples` is how many samples it has (the arrays' length, or the header's count).
Status ValidateMetadata(const v1::ImportedRun& r, std::int64_t samples, const std::string& where) {
  if (r.id().empty()) return Status::InvalidArgument(where + ".id: must not be empty");
  if (!(r.supply_v() > 0.0) || !std::isfinite(r.supply_v()))
    return Status::InvalidArgument(where + ".supply_V: must be > 0, got " + FormatNumber(r.supply_v()));
  VB_RETURN_IF_ERROR(SpecBound(where + ".supply_V", "conditions.supply_V", r.supply_v()));
  if (!(r.supply_pressure_pa() >= 0.0) || !std::isfinite(r.supply_pressure_pa()))
    return Status::InvalidArgument(where + ".supply_pressure_Pa: must be >= 0, got " + FormatNumber(r.supply_pressure_pa()));
  VB_RETURN_IF_ERROR(SpecBound(where + ".supply_pressure_Pa", "conditions.supply_pressure_Pa", r.supply_pressure_pa()));
  VB_RETURN_IF_ERROR(InRange(where + ".t_start_s", r.t_start_s(), 0.0, kMaxStart_s, "s"));
  VB_RETURN_IF_ERROR(InRange(where + ".sample_period_s", r.sample_period_s(), kMinSamplePeriod_s, kMaxSamplePeriod_s, "s"));
  if (!ParseSplit(r.split()).ok())
    return Status::InvalidArgument(where + ".split: must be \"fit\", \"holdout\" or empty, got \"" + r.split() + "\"");
  if (samples < 2)
    return Status::InvalidArgument(where + ".gate: at least 2 samples are needed, got " + std::to_string(samples));
  if (samples > kMaxSamplesPerRun)
    return Status::ResourceExhausted(where + ".samples: " + std::to_string(samples) + " exceed " +
                                     std::to_string(kMaxSamplesPerRun) + " per run; split the run");
  return Status::Ok();
}

// Samples [first, first + n) of a run; x and v are null when the run has no such column.
Status CheckSamples(const std::string& where, std::size_t first, const std::int32_t* gate, const double* i,
                    const double* x, const double* v, std::size_t n) {
  for (std::size_t j = 0; j < n; ++j) {
    auto at = [&] { return "[" + std::to_string(first + j) + "]"; };
    if (gate[j] != 0 && gate[j] != 1)
      return Status::InvalidArgument(where + ".gate" + at() + ": must be 0 or 1, got " + std::to_string(gate[j]));
    if (!std::isfinite(i[j]) || std::abs(i[j]) > kMaxAbsCurrent_A)
      return InRange(where + ".i_A" + at(), i[j], -kMaxAbsCurrent_A, kMaxAbsCurrent_A, "A");
    if (x != nullptr && !std::isnan(x[j]) && !(std::abs(x[j]) <= kMaxAbsPosition_m))
      return InRange(where + ".x_m" + at(), x[j], -kMaxAbsPosition_m, kMaxAbsPosition_m, "m (or NaN: not measured)");
    if (v != nullptr && !std::isnan(v[j]) && !(std::abs(v[j]) <= kMaxAbsVoltage_V))
      return InRange(where + ".v_coil_V" + at(), v[j], -kMaxAbsVoltage_V, kMaxAbsVoltage_V, "V (or NaN: not measured)");
  }
  return Status::Ok();
}

// Samples of one run, checked and appended to the store as chunks of kChunkSamples while they arrive.
class RunWriter {
 public:
  RunWriter(db::Store* store, db::Lease lease, const v1::ImportedRun& meta, bool has_x, bool has_v,
            std::string where)
      : store_(store), lease_(lease), period_s_(meta.sample_period_s()), has_x_(has_x), has_v_(has_v),
        where_(std::move(where)) {
    channels_ = {"t_s", "gate", "i_A"};
    if (has_x_) channels_.push_back("x_m");
    if (has_v_) channels_.push_back("v_coil_V");
  }

  // n samples; x and v are null when the run has no such column.
  Status Add(const std::int32_t* gate, const double* i, const double* x, const double* v, std::size_t n) {
    VB_RETURN_IF_ERROR(CheckSamples(where_, received_, gate, i, x, v, n));
    for (std::size_t j = 0; j < n; ++j) {
      gate_.push_back(gate[j]);
      i_.push_back(i[j]);
      if (has_x_) x_.push_back(x[j]);
      if (has_v_) v_.push_back(v[j]);
      if (gate_.size() == kChunkSamples) VB_RETURN_IF_ERROR(Flush());
    }
    received_ += n;
    return Status::Ok();
  }
  Status Close() { return gate_.empty() ? Status::Ok() : Flush(); }
  std::int64_t received() const { return static_cast<std::int64_t>(received_); }

 private:
  Status Flush() {
    const std::size_t m = gate_.size();
    const std::size_t from = flushed_;
    db::TraceChunk c;
    c.index = index_++;
    c.t0_s = static_cast<double>(from) * period_s_;
    c.sample_period_s = period_s_;
    c.samples = static_cast<std::int32_t>(m);
    c.channels = channels_;
    c.data.reserve(channels_.size() * m);
    for (std::size_t j = 0; j < m; ++j) c.data.push_back(static_cast<double>(from + j) * period_s_);
    for (std::size_t j = 0; j < m; ++j) c.data.push_back(gate_[j]);
    c.data.insert(c.data.end(), i_.begin(), i_.end());
    c.data.insert(c.data.end(), x_.begin(), x_.end());
    c.data.insert(c.data.end(), v_.begin(), v_.end());
    flushed_ += m;
    gate_.clear();
    i_.clear();
    x_.clear();
    v_.clear();
    return store_->AppendTraceChunk(lease_, c);
  }

  db::Store* store_;
  db::Lease lease_;
  double period_s_;
  bool has_x_, has_v_;
  std::string where_;
  std::vector<std::string> channels_;
  std::vector<std::int32_t> gate_;
  std::vector<double> i_, x_, v_;
  std::size_t received_ = 0, flushed_ = 0;
  std::int32_t index_ = 0;
};

std::mutex import_mu;  // one import at a time: the claims below must find this import's runs

// What both RPCs share: the request's checks (metadata only when `streamed`), the runs' records.
StatusOr<std::vector<db::RunRecord>> ImportRecords(const v1::ImportRunsRequest& req, bool streamed,
                                                   std::uint32_t max_runs) {
  if (req.dataset().empty()) return Status::InvalidArgument("dataset: must name the dataset");
  if (req.runs_size() == 0) return Status::InvalidArgument("runs: at least one run is needed");
  const std::string model = req.model().empty() ? model::kDefaultPreset : req.model();
  if (!model::Preset(model).ok()) return Status::InvalidArgument("model: unknown model '" + model + "'");
  if (static_cast<std::uint32_t>(req.runs_size()) > max_runs)
    return Status::ResourceExhausted("runs: " + std::to_string(req.runs_size()) + " runs exceed the server limit of " +
                                     std::to_string(max_runs));
  std::vector<db::RunRecord> records;
  std::map<std::string, int> ids;
  for (int k = 0; k < req.runs_size(); ++k) {
    const auto& r = req.runs(k);
    const std::string where = "runs[" + std::to_string(k) + "]";
    const int arrays = r.gate_size() + r.i_a_size() + r.x_m_size() + r.v_coil_v_size();
    if (streamed && arrays > 0)
      return Status::InvalidArgument(where + ": the header carries no samples (they follow as ImportSamples parts)");
    const std::int64_t n = streamed ? r.samples() : r.gate_size();
    VB_RETURN_IF_ERROR(ValidateMetadata(r, n, where));
    if (auto [it, fresh] = ids.emplace(r.id(), k); !fresh)
      return Status::InvalidArgument(where + ".id: \"" + r.id() + "\" is also runs[" + std::to_string(it->second) +
                                     "].id; run ids must be unique in a dataset");
    if (!streamed) {
      if (r.i_a_size() != r.gate_size())
        return Status::InvalidArgument(where + ".i_A: " + std::to_string(r.i_a_size()) + " samples for " +
                                       std::to_string(r.gate_size()) + " gate samples");
      for (const auto* col : {&r.x_m(), &r.v_coil_v()})
        if (col->size() != 0 && col->size() != r.gate_size())
          return Status::InvalidArgument(where + (col == &r.x_m() ? ".x_m: " : ".v_coil_V: ") +
                                         std::to_string(col->size()) + " samples for " +
                                         std::to_string(r.gate_size()));
    }
    if (k > 0 && r.t_start_s() < req.runs(k - 1).t_start_s())
      return Status::InvalidArgument(where + ".t_start_s: runs must be in time order");
    v1::ExperimentSpec spec;
    spec.set_name(r.id());
    spec.set_description(req.description());
    spec.mutable_bench()->set_kind(kImportedKind);
    spec.mutable_bench()->mutable_model()->set_preset(model);
    spec.mutable_conditions()->set_supply_v(r.supply_v());
    spec.mutable_conditions()->set_supply_pressure_pa(r.supply_pressure_pa());
    spec.set_duration_s(static_cast<double>(n - 1) * r.sample_period_s());
    spec.set_never_requeue(true);
    for (const std::string& tag : {std::string("imported"), "dataset:" + req.dataset(),
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
  return records;
}

// Submits the records as batch "import:<dataset>" and claims its runs for the importer, in order.
StatusOr<std::vector<db::RunRecord>> SubmitAndClaim(db::Store* store, const std::string& user,
                                                    const std::string& dataset, std::vector<db::RunRecord> records,
                                                    std::int64_t* batch_id) {
  std::lock_guard<std::mutex> lock(import_mu);
  std::vector<std::int64_t> ids;
  auto batch = store->SubmitBatch(user, "import:" + dataset, "{}", std::move(records), &ids);
  if (!batch.ok()) return batch.status();
  *batch_id = *batch;
  std::vector<db::RunRecord> claimed;
  for (std::int64_t id : ids) {
    auto c = store->ClaimNext(db::BenchClaim(kImportedKind, "import"));
    if (!c.ok()) return c.status();
    if (!c->has_value() || (*c)->id != id)
      return Status::Internal("import: run " + std::to_string(id) + " was not next in the queue");
    claimed.push_back(std::move(**c));
  }
  return claimed;
}

// The runs from `first` on end failed with the reason (the import stopped there); earlier ones stay done.
void FailFrom(db::Store* store, const std::vector<db::RunRecord>& runs, std::size_t first, const std::string& why) {
  for (std::size_t k = first; k < runs.size(); ++k)
    (void)store->Finish(db::LeaseOf(runs[k]), db::RunStatus::kFailed, "import failed: " + why, {});
}

}  // namespace

grpc::Status BenchServiceImpl::ImportRuns(grpc::ServerContext* ctx, const v1::ImportRunsRequest* req,
                                          v1::SubmitRunResponse* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  auto records = ImportRecords(*req, false, settings_->limits.max_runs_per_submission());
  if (!records.ok()) return ToGrpcStatus(records.status());
  // Every sample is checked before anything is stored.
  for (int k = 0; k < req->runs_size(); ++k) {
    const auto& r = req->runs(k);
    if (auto st = CheckSamples("runs[" + std::to_string(k) + "]", 0, r.gate().data(), r.i_a().data(),
                               r.x_m_size() > 0 ? r.x_m().data() : nullptr,
                               r.v_coil_v_size() > 0 ? r.v_coil_v().data() : nullptr,
                               static_cast<std::size_t>(r.gate_size()));
        !st.ok())
      return ToGrpcStatus(st);
  }
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  std::int64_t batch_id = 0;
  auto runs = SubmitAndClaim(store->get(), who.user, req->dataset(), std::move(*records), &batch_id);
  if (!runs.ok()) return ToGrpcStatus(runs.status());
  for (int k = 0; k < req->runs_size(); ++k) {
    const auto& r = req->runs(k);
    const db::RunRecord& run = (*runs)[static_cast<std::size_t>(k)];
    const bool has_x = r.x_m_size() > 0, has_v = r.v_coil_v_size() > 0;
    RunWriter writer(store->get(), db::LeaseOf(run), r, has_x, has_v, "runs[" + std::to_string(k) + "]");
    Status st = writer.Add(r.gate().data(), r.i_a().data(), has_x ? r.x_m().data() : nullptr,
                           has_v ? r.v_coil_v().data() : nullptr, static_cast<std::size_t>(r.gate_size()));
    if (st.ok()) st = writer.Close();
    if (st.ok()) st = (*store)->Finish(db::LeaseOf(run), db::RunStatus::kDone, "imported from " + req->dataset(), {});
    if (!st.ok()) {
      FailFrom(store->get(), *runs, static_cast<std::size_t>(k), st.message());
      return ToGrpcStatus(st.WithContext("runs[" + std::to_string(k) + "]"));
    }
    resp->add_run_ids(run.id);
  }
  resp->set_batch_id(batch_id);
  return grpc::Status::OK;
}

grpc::Status BenchServiceImpl::ImportRunsStream(grpc::ServerContext* ctx, grpc::ServerReader<v1::ImportRunsPart>* reader,
                                                v1::SubmitRunResponse* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  v1::ImportRunsPart part;
  if (!reader->Read(&part)) return ToGrpcStatus(Status::InvalidArgument("header: the stream is empty"));
  if (!part.has_header())
    return ToGrpcStatus(Status::InvalidArgument("header: the first part must be the header (ImportRunsRequest)"));
  const v1::ImportRunsRequest header = part.header();
  auto records = ImportRecords(header, true, settings_->limits.max_runs_per_submission());
  if (!records.ok()) return ToGrpcStatus(records.status().WithContext("header"));
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  std::int64_t batch_id = 0;
  auto runs = SubmitAndClaim(store->get(), who.user, header.dataset(), std::move(*records), &batch_id);
  if (!runs.ok()) return ToGrpcStatus(runs.status());

  std::size_t k = 0;  // the run receiving samples
  std::unique_ptr<RunWriter> writer;
  auto open = [&] {
    const auto& r = header.runs(static_cast<int>(k));
    writer = std::make_unique<RunWriter>(store->get(), db::LeaseOf((*runs)[k]), r, r.has_x_m(), r.has_v_coil_v(),
                                         "runs[" + std::to_string(k) + "]");
  };
  auto fail = [&](const Status& st) {
    FailFrom(store->get(), *runs, k, st.message());
    return ToGrpcStatus(st);
  };
  open();
  std::int64_t part_index = 0;
  while (reader->Read(&part)) {
    ++part_index;
    const std::string where = "parts[" + std::to_string(part_index) + "]";
    if (!part.has_samples()) return fail(Status::InvalidArgument(where + ": only the first part is a header"));
    const v1::ImportSamples& s = part.samples();
    if (k >= runs->size() || s.run_index() != static_cast<std::int32_t>(k))
      return fail(Status::InvalidArgument(where + ".run_index: expected " + std::to_string(k) + " (runs[" +
                                          std::to_string(k) + "] has " + std::to_string(writer->received()) + " of " +
                                          std::to_string(header.runs(static_cast<int>(k)).samples()) +
                                          " samples), got " + std::to_string(s.run_index())));
    const auto& r = header.runs(static_cast<int>(k));
    const int n = s.gate_size();
    if (s.i_a_size() != n || s.x_m_size() != (r.has_x_m() ? n : 0) || s.v_coil_v_size() != (r.has_v_coil_v() ? n : 0))
      return fail(Status::InvalidArgument(where + ": " + std::to_string(n) + " gate samples with " +
                                          std::to_string(s.i_a_size()) + " i_A, " + std::to_string(s.x_m_size()) +
                                          " x_m and " + std::to_string(s.v_coil_v_size()) +
                                          " v_coil_V (the header says x_m " + (r.has_x_m() ? "yes" : "no") +
                                          ", v_coil_V " + (r.has_v_coil_v() ? "yes" : "no") + ")"));
    if (writer->received() + n > r.samples())
      return fail(Status::InvalidArgument(where + ": runs[" + std::to_string(k) + "] gets more than the " +
                                          std::to_string(r.samples()) + " samples its header announced"));
    if (auto st = writer->Add(s.gate().data(), s.i_a().data(), r.has_x_m() ? s.x_m().data() : nullptr,
                              r.has_v_coil_v() ? s.v_coil_v().data() : nullptr, static_cast<std::size_t>(n));
        !st.ok())
      return fail(st);
    if (writer->received() == r.samples()) {
      Status st = writer->Close();
      if (st.ok())
        st = (*store)->Finish(db::LeaseOf((*runs)[k]), db::RunStatus::kDone, "imported from " + header.dataset(), {});
      if (!st.ok()) return fail(st.WithContext("runs[" + std::to_string(k) + "]"));
      resp->add_run_ids((*runs)[k].id);
      ++k;
      if (k < runs->size()) open();
    }
  }
  if (ctx->IsCancelled()) return fail(Status::Aborted("the client cancelled the import"));
  if (k < runs->size())
    return fail(Status::InvalidArgument("runs[" + std::to_string(k) + "]: the stream ended after " +
                                        std::to_string(writer->received()) + " of " +
                                        std::to_string(header.runs(static_cast<int>(k)).samples()) + " samples"));
  resp->set_batch_id(batch_id);
  return grpc::Status::OK;
}

}  // namespace vb::server
