// BenchServiceImpl's records besides runs (docs/regress.md, docs/store.md): named, versioned baselines, regression
// results and the store as a whole, read and written through the store's own record functions (db/records.h) on
// either engine. Every door reaches them here: benchctl --local through the local service, benchctl --server and
// the other doors through the server, so a baseline lives in the store of the service that ran its runs.
#include <string>
#include <vector>

#include "db/pg_copy.h"
#include "regress/compare.h"
#include "service/grpc_status.h"
#include "service/service.h"

namespace vb::server {

namespace v1 = valvebench::v1;

namespace {

void ToProto(const db::BaselineRecord& b, v1::Baseline* out) {
  out->set_name(b.name);
  out->set_version(b.version);
  out->set_created_unix_s(b.created_unix_s);
  out->set_source(b.source);
  out->set_note(b.note);
  for (const db::BaselineEntry& e : b.entries) {
    v1::BaselineEntry* p = out->add_entries();
    p->set_case_name(e.case_name);
    p->set_metric(e.metric);
    p->set_mean(e.mean);
    p->set_spread(e.spread);
    p->set_n(e.n);
  }
}

void AddCounts(const std::vector<std::pair<std::string, std::int64_t>>& counts,
               google::protobuf::RepeatedPtrField<v1::StoreCount>* out) {
  for (const auto& [name, n] : counts) {
    v1::StoreCount* c = out->Add();
    c->set_name(name);
    c->set_count(n);
  }
}

}  // namespace

grpc::Status BenchServiceImpl::SaveBaseline(grpc::ServerContext* ctx, const v1::SaveBaselineRequest* req,
                                            v1::Baseline* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  const v1::Baseline& b = req->baseline();
  // The store checks the values (db/checks.cc, ValidateBaseline) and names them as this request does:
  // "baseline.name", "baseline.entries[k].spread".
  std::vector<db::BaselineEntry> entries;
  entries.reserve(b.entries_size());
  for (const v1::BaselineEntry& e : b.entries())
    entries.push_back({e.case_name(), e.metric(), e.mean(), e.spread(), e.n()});
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  auto version = (*store)->SaveBaseline(b.name(), b.source(), b.note(), entries);
  if (!version.ok()) return ToGrpcStatus(version.status());
  auto saved = (*store)->GetBaseline(b.name(), *version);
  if (!saved.ok()) return ToGrpcStatus(saved.status());
  ToProto(*saved, resp);
  return grpc::Status::OK;
}

grpc::Status BenchServiceImpl::GetBaseline(grpc::ServerContext* ctx, const v1::GetBaselineRequest* req,
                                           v1::Baseline* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  if (req->name().empty()) return ToGrpcStatus(Status::InvalidArgument("name: must not be empty"));
  if (req->version() < 0)
    return ToGrpcStatus(Status::InvalidArgument("version: must be >= 1 (0 = the newest), got " +
                                                std::to_string(req->version())));
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  auto rec = (*store)->GetBaseline(req->name(), req->version());  // NOT_FOUND: "baseline 'x' has no version 9"
  if (!rec.ok()) return ToGrpcStatus(rec.status());
  ToProto(*rec, resp);
  return grpc::Status::OK;
}

grpc::Status BenchServiceImpl::ListBaselines(grpc::ServerContext* ctx, const v1::ListBaselinesRequest* /*req*/,
                                             v1::ListBaselinesResponse* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  auto list = (*store)->ListBaselines();
  if (!list.ok()) return ToGrpcStatus(list.status());
  for (const db::BaselineRecord& b : *list) ToProto(b, resp->add_baselines());
  return grpc::Status::OK;
}

grpc::Status BenchServiceImpl::SaveRegression(grpc::ServerContext* ctx, const v1::SaveRegressionRequest* req,
                                              v1::SaveRegressionResponse* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  if (req->result_json().empty()) return ToGrpcStatus(Status::InvalidArgument("result_json: must not be empty"));
  const regress::Json j = regress::Json::parse(req->result_json(), nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded()) return ToGrpcStatus(Status::InvalidArgument("result_json: not JSON"));
  auto parse = [&j]() -> StatusOr<regress::RegressResult> {
    try {  // a member of the wrong type (a number for "suite") throws from nlohmann's value()
      return regress::ResultFromJson(j);
    } catch (const regress::Json::exception& e) {
      return Status::InvalidArgument(std::string("not a regression result: ") + e.what());
    }
  };
  auto r = parse();
  if (!r.ok()) return ToGrpcStatus(r.status().WithContext("result_json"));
  if (r->suite.empty()) return ToGrpcStatus(Status::InvalidArgument("result_json.suite: must not be empty"));
  if (r->batch_id < 0)
    return ToGrpcStatus(Status::InvalidArgument("result_json.batch_id: must be >= 0, got " +
                                                std::to_string(r->batch_id)));
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  if (r->batch_id != 0) {  // retention protects the batch a result names: it must be this store's
    db::RunFilter in_batch;
    in_batch.batch_id = r->batch_id;
    auto n = (*store)->CountRuns(in_batch);
    if (!n.ok()) return ToGrpcStatus(n.status());
    if (*n == 0)
      return ToGrpcStatus(Status::NotFound("result_json.batch_id: batch " + std::to_string(r->batch_id) +
                                           " has no runs in this store"));
  }
  db::RegressionRecord rec;
  rec.suite = r->suite;
  rec.baseline_name = r->baseline_name;
  rec.baseline_version = r->baseline_version;
  rec.batch_id = r->batch_id;
  rec.created_unix_s = r->created_unix_s;
  rec.verdict = r->verdict();
  rec.result_json = req->result_json();  // as sent: whatever the result holds besides what is parsed stays
  auto id = (*store)->SaveRegression(rec);
  if (!id.ok()) return ToGrpcStatus(id.status());
  resp->set_id(*id);
  return grpc::Status::OK;
}

grpc::Status BenchServiceImpl::GetRegression(grpc::ServerContext* ctx, const v1::GetRegressionRequest* req,
                                             v1::Regression* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  if (req->id() < 1)
    return ToGrpcStatus(Status::InvalidArgument("id: must be >= 1, got " + std::to_string(req->id())));
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  auto rec = (*store)->GetRegression(req->id());  // NOT_FOUND: "regression 7 not found"
  if (!rec.ok()) return ToGrpcStatus(rec.status());
  resp->set_id(rec->id);
  resp->set_suite(rec->suite);
  resp->set_baseline_name(rec->baseline_name);
  resp->set_baseline_version(rec->baseline_version);
  resp->set_batch_id(rec->batch_id);
  resp->set_night(rec->night);
  resp->set_created_unix_s(rec->created_unix_s);
  resp->set_verdict(rec->verdict);
  resp->set_result_json(rec->result_json);
  return grpc::Status::OK;
}

grpc::Status BenchServiceImpl::DescribeStore(grpc::ServerContext* ctx, const v1::DescribeStoreRequest* /*req*/,
                                             v1::DescribeStoreResponse* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  auto info = db::ReadStoreInfo(pool_->location());  // its own connection: counts over the whole store
  if (!info.ok()) return ToGrpcStatus(info.status());
  resp->set_engine(info->engine);
  resp->set_location(info->location);
  resp->set_schema_version(info->schema_version);
  AddCounts(info->runs_by_status, resp->mutable_runs_by_status());
  AddCounts(info->rows, resp->mutable_rows());
  resp->set_trace_bytes(info->trace_bytes);
  return grpc::Status::OK;
}

}  // namespace vb::server
