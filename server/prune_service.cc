// BenchServiceImpl::PruneRuns: retention through the API (admin role), Store::Prune on the server's store
// (docs/store.md, "Retention"). Besides what the store protects by itself (batches of regression results and
// nights, baselines taken from local batches), the batch that the nights' baseline file was taken from stays.
#include <chrono>
#include <cmath>
#include <string>

#include "common/format.h"
#include "proto/api_convert.h"
#include "server/config.h"
#include "server/grpc_status.h"
#include "server/service.h"

namespace vb::server {

namespace v1 = valvebench::v1;

namespace {

// The batch a baseline taken on a server names ("server lab:50051 batch 12", "suite ci (server lab:50051 batch
// 12, seed 1)"), else 0 (benchctl/regress_commands.cc writes these sources).
std::int64_t ServerBatchOfBaselineSource(const std::string& source) {
  const std::size_t server = source.find("server ");
  if (server == std::string::npos) return 0;
  const std::size_t at = source.find(" batch ", server);
  if (at == std::string::npos) return 0;
  std::int64_t batch = 0;
  std::size_t k = at + 7;
  if (k >= source.size() || source[k] < '0' || source[k] > '9') return 0;
  for (; k < source.size() && source[k] >= '0' && source[k] <= '9' && batch < (std::int64_t{1} << 56); ++k)
    batch = batch * 10 + (source[k] - '0');
  return batch;
}

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
  if (auto st = Authorize(ctx, Role::kAdmin, &who); !st.ok()) return st;
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
  if (!settings_->nights.baseline_path.empty()) {
    auto b = LoadBaselineFile(settings_->nights.baseline_path);
    if (!b.ok()) {
      // Without the file nobody can tell which batch it came from: refuse rather than risk deleting it.
      return ToGrpcStatus(Status::FailedPrecondition("nights.baseline_file " + settings_->nights.baseline_path +
                                                     " cannot be read, so the runs it references cannot be "
                                                     "protected: " + b.status().message()));
    }
    if (const std::int64_t batch = ServerBatchOfBaselineSource(b->source); batch > 0) {
      p.protected_batches.push_back(batch);
      p.protected_why = "the nights' baseline file (" + b->name + ", source \"" + b->source + "\")";
    }
  }
  if (!std::isfinite(p.finished_before_unix_s) || p.finished_before_unix_s <= 0)
    return ToGrpcStatus(Status::InvalidArgument("older_than_s: reaches before 1970"));
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  auto result = (*store)->Prune(p);
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
