// BenchServiceImpl::PruneRuns: retention through the API (admin role), Store::Prune on the server's store
// (docs/store.md, "Retention") through PruneWithServerRules (service/prune_rules.h), which the retention scheduler
// uses too: besides what the store protects by itself, the batch the nights' baseline file was taken from stays.
#include <chrono>
#include <cmath>
#include <string>

#include "common/format.h"
#include "proto/api_convert.h"
#include "service/grpc_status.h"
#include "service/prune_rules.h"
#include "service/service.h"

namespace vb::server {

namespace v1 = valvebench::v1;

namespace {

void ToProto(const db::PruneDecision& d, v1::PruneDecision* out) {
  out->set_run_id(d.run_id);
  out->set_batch_id(d.batch_id);
  out->set_name(d.name);
  out->set_status(api::ToProto(d.status));
  out->set_finished_unix_s(d.finished_unix_s);
  out->set_why(d.why);
}

}  // namespace

grpc::Status BenchServiceImpl::PruneRuns(grpc::ServerContext* ctx, const v1::PruneRunsRequest* req,
                                         v1::PruneRunsResponse* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  if (!std::isfinite(req->older_than_s()) || req->older_than_s() <= 0)
    return ToGrpcStatus(Status::InvalidArgument("older_than_s: must be a finite number of seconds > 0, got " +
                                                FormatExact(req->older_than_s())));
  if (req->keep_last() < 0)
    return ToGrpcStatus(Status::InvalidArgument("keep_last: must be >= 0, got " + std::to_string(req->keep_last())));
  const double now =
      std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  db::PruneRequest p;
  p.finished_before_unix_s = now - req->older_than_s();
  p.keep_last = req->keep_last();
  p.dry_run = req->dry_run();
  if (!std::isfinite(p.finished_before_unix_s) || p.finished_before_unix_s <= 0)
    return ToGrpcStatus(Status::InvalidArgument("older_than_s: reaches before 1970"));
  // The same path the retention scheduler takes (service/prune_rules.h): one set of rules.
  auto result = PruneWithServerRules(pool_, settings_->nights, p);
  if (!result.ok()) return ToGrpcStatus(result.status());
  for (const auto& d : result->deleted) ToProto(d, resp->add_deleted());
  for (const auto& d : result->kept) ToProto(d, resp->add_kept());
  resp->set_newer_kept(result->newer_kept);
  resp->set_trace_bytes(result->trace_bytes);
  resp->set_batches_deleted(result->batches_deleted);
  resp->set_cutoff_unix_s(p.finished_before_unix_s);
  resp->set_dry_run(p.dry_run);
  return grpc::Status::OK;
}

}  // namespace vb::server
