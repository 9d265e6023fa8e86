#include "benchctl/backend.h"

#include <cstdio>
#include <cstdlib>

#include "client/batch_wait.h"
#include "proto/api_convert.h"

namespace vb::benchctl {
namespace {

namespace v1 = valvebench::v1;

constexpr double kRunDeadline_s = 6 * 3600.0;  // one run of a batch, waited for

}  // namespace

std::string DefaultLocalStorePath() {
  if (const char* p = std::getenv("VALVEBENCH_DB"); p != nullptr && *p != '\0') return p;
  if (const char* home = std::getenv("HOME"); home != nullptr && *home != '\0')
    return std::string(home) + "/.local/share/valvebench/local.db";
  return "valvebench-local.db";
}

RunView FromProto(const v1::Run& r) {
  RunView v;
  v.id = r.id();
  v.batch_id = r.batch_id();
  v.key = api::FromProto(r.key());
  v.controller = r.controller();
  v.status = api::FromProto(r.status()).value_or(RunStatus::kQueued);
  v.reason = r.reason();
  for (const auto& [k, x] : r.metrics()) v.metrics[k] = x;
  v.bench = r.bench();
  v.host = r.host();
  v.duration_s = r.duration_s();
  v.submitter = r.submitter();
  v.priority = r.priority();
  v.progress = r.progress();
  v.result_waiting_since_unix_s = r.result_waiting_since_unix_s();
  v.submitted_unix_s = r.submitted_unix_s();
  v.started_unix_s = r.started_unix_s();
  v.finished_unix_s = r.finished_unix_s();
  v.tags.assign(r.tags().begin(), r.tags().end());
  v.split = r.split();
  if (r.has_t_start_s()) v.t_start_s = r.t_start_s();
  if (r.has_spec()) v.spec = r.spec();
  if (r.has_execution()) v.execution = r.execution();
  for (const auto& c : r.history())
    v.history.push_back({api::FromProto(c.status()).value_or(RunStatus::kQueued), c.at_unix_s(), c.reason()});
  return v;
}

Backend::Backend(std::unique_ptr<client::Client> client, std::string where, std::unique_ptr<server::LocalService> local)
    : where_(std::move(where)), local_(std::move(local)), c_(std::move(client)) {}

Backend::Backend(Status why, std::string where) : broken_(std::move(why)), where_(std::move(where)) {}

Backend::~Backend() = default;

Status Backend::Named(Status st, bool always) const {
  if ((always || (local_ != nullptr && st.code() == StatusCode::kNotFound)) &&
      st.message().find(where_) == std::string::npos)
    return st.WithContext(where_);
  return st;
}

#define VB_BACKEND_READY() \
  if (!broken_.ok()) return broken_

StatusOr<std::int64_t> Backend::RunBatch(const std::vector<experiment::ExperimentSpec>& specs,
                                         const std::vector<RunKey>& keys, const std::string& batch_name,
                                         const std::string& /*batch_json*/) {
  VB_BACKEND_READY();
  std::vector<v1::RunKey> key_protos;
  for (const auto& k : keys) key_protos.push_back(api::ToProto(k));
  auto resp = c_->SubmitBatch(specs, batch_name, key_protos);
  if (!resp.ok()) return Named(resp.status());
  std::fprintf(stderr, "%s: batch %lld, %d runs on %s\n", batch_name.c_str(), static_cast<long long>(resp->batch_id()),
               resp->run_ids_size(), where_.c_str());
  auto st = WaitForRuns({resp->run_ids().begin(), resp->run_ids().end()}, [&](std::int64_t id) {
    if (!executes_here()) return;  // a server's runs: the caller reports them
    if (auto r = c_->GetRun(id); r.ok() && r->has_execution())
      std::fprintf(stderr, "  %s: %s\n", api::FromProto(r->key()).DisplayName().c_str(),
                   ExecutionBrief(FromProto(*r)).c_str());
  });
  if (!st.ok()) return st;
  return resp->batch_id();
}

Status Backend::WaitForRuns(const std::vector<std::int64_t>& run_ids,
                            const std::function<void(std::int64_t)>& on_ended) {
  VB_BACKEND_READY();
  return Named(client::WaitForRuns(*c_, run_ids, kRunDeadline_s, on_ended));
}

StatusOr<v1::Run> Backend::ApiRun(std::int64_t run_id) {
  VB_BACKEND_READY();
  auto r = c_->GetRun(run_id);
  if (!r.ok()) return Named(r.status());
  return r;
}

StatusOr<client::ReportRuns> Backend::ReportRuns(std::int64_t batch, const std::vector<std::int64_t>& run_ids,
                                                 const client::ReportLimits& limits) {
  VB_BACKEND_READY();
  auto r = client::FetchReportRuns(*c_, batch, run_ids, limits);
  if (!r.ok()) return Named(r.status());
  return r;
}

StatusOr<std::vector<RunView>> Backend::Runs(std::int64_t batch, const std::vector<std::int64_t>& run_ids) {
  VB_BACKEND_READY();
  std::vector<RunView> out;
  auto add = [&](const v1::Run& r) { out.push_back(FromProto(r)); };
  if (batch == 0) {
    for (auto id : run_ids) {
      auto r = c_->GetRun(id);
      if (!r.ok()) return Named(r.status());
      add(*r);
    }
    return out;
  }
  v1::ListRunsRequest req;
  req.set_batch_id(batch);
  req.set_page_size(1000);
  req.set_order_by("id");  // a batch in run order
  for (;;) {
    auto resp = c_->ListRuns(req);
    if (!resp.ok()) return Named(resp.status());
    for (const auto& r : resp->runs()) add(r);
    if (resp->next_page_token().empty()) break;
    req.set_page_token(resp->next_page_token());
  }
  if (out.empty())
    return Status::NotFound(where_ + ": batch " + std::to_string(batch) + " not found");
  // ListRuns leaves the spec out; reports show it (GetRun has it).
  for (auto& v : out) {
    auto r = c_->GetRun(v.id);
    if (!r.ok()) return Named(r.status());
    if (r->has_spec()) v.spec = r->spec();
  }
  return out;
}

StatusOr<experiment::Comparison> Backend::Compare(std::int64_t batch, const std::vector<std::int64_t>& run_ids) {
  VB_BACKEND_READY();
  auto c = RemoteComparison(*c_, batch, run_ids);
  if (!c.ok()) return Named(c.status());
  return c;
}

StatusOr<Trace> Backend::GetTrace(std::int64_t run_id) {
  VB_BACKEND_READY();
  auto t = c_->GetTrace(run_id);
  if (!t.ok()) return Named(t.status());
  return t;
}

StatusOr<v1::ListBenchesResponse> Backend::Benches() {
  VB_BACKEND_READY();
  return c_->Benches();
}

StatusOr<v1::GetBenchHealthResponse> Backend::BenchHealth(const std::string& bench) {
  VB_BACKEND_READY();
  return c_->GetBenchHealth(bench);
}

StatusOr<v1::DiagnoseRunsResponse> Backend::DiagnoseRuns(const v1::DiagnoseRunsRequest& request) {
  VB_BACKEND_READY();
  // A person at a terminal waits as long as the diagnosis takes (moving valves: minutes), not the web's 300 s.
  return c_->DiagnoseRuns(request, 3600.0);
}

StatusOr<Submitted> Backend::Submit(const experiment::ExperimentSpec& spec, bool realtime) {
  VB_BACKEND_READY();
  experiment::ExperimentSpec s = spec;
  if (realtime) s.set_realtime(true);
  auto resp = c_->Submit(s);
  if (!resp.ok()) return Named(resp.status());
  Submitted out;
  out.batch_id = resp->batch_id();
  out.run_ids.assign(resp->run_ids().begin(), resp->run_ids().end());
  return out;
}

std::optional<experiment::Trace> Backend::KeptTrace(std::int64_t run_id) const {
  if (local_ == nullptr) return std::nullopt;
  return local_->KeptTrace(run_id);
}

StatusOr<RunView> Backend::GetRun(std::int64_t run_id) {
  VB_BACKEND_READY();
  auto r = c_->GetRun(run_id);
  if (!r.ok()) return Named(r.status());
  return FromProto(*r);
}

StatusOr<std::vector<RunView>> Backend::ListRuns(const RunFilter& filter, bool* more, std::int64_t* total) {
  VB_BACKEND_READY();
  v1::ListRunsRequest req;
  if (filter.status) req.set_status(api::ToProto(*filter.status));
  req.set_batch_id(filter.batch_id);
  req.set_tag(filter.tag);
  req.set_page_size(filter.limit);
  req.set_order_by("submitted desc");  // newest first (ListRuns' default, said here)
  auto resp = c_->ListRuns(req);
  if (!resp.ok()) return Named(resp.status());
  *more = !resp->next_page_token().empty();
  if (total != nullptr) *total = resp->total_size();
  std::vector<RunView> out;
  for (const auto& r : resp->runs()) out.push_back(FromProto(r));
  return out;
}

StatusOr<v1::GetQueueResponse> Backend::Queue() {
  VB_BACKEND_READY();
  auto q = c_->GetQueue();
  if (!q.ok()) return Named(q.status());
  return q;
}

StatusOr<RunView> Backend::Cancel(std::int64_t run_id, const std::string& reason) {
  VB_BACKEND_READY();
  auto r = c_->Cancel(run_id, reason);
  if (!r.ok()) return Named(r.status());
  return FromProto(*r);
}

Status Backend::Watch(std::int64_t run_id, const std::function<bool(const RunView&)>& on_event) {
  VB_BACKEND_READY();
  return Named(c_->Watch(run_id, kRunDeadline_s, -1.0, [&](const v1::RunEvent& ev) {
    RunView v;
    v.id = run_id;
    v.status = api::FromProto(ev.status()).value_or(RunStatus::kQueued);
    v.progress = ev.progress();
    v.reason = ev.reason();
    return on_event(v) && !v.ended();
  }));
}

StatusOr<v1::SubmitRunResponse> Backend::Import(const v1::ImportRunsRequest& request) {
  VB_BACKEND_READY();
  auto r = c_->ImportRuns(request);
  if (!r.ok()) return Named(r.status());
  return r;
}

Status Backend::RecordsKept() const {
  if (!keeps_runs())
    return Status::InvalidArgument("--no-store: baselines and regression results need a store that is kept "
                                   "(--db FILE, or --server ADDR)");
  return Status::Ok();
}

StatusOr<regress::Baseline> Backend::SaveBaseline(const regress::Baseline& baseline) {
  VB_BACKEND_READY();
  VB_RETURN_IF_ERROR(RecordsKept());
  auto b = c_->SaveBaseline(baseline);
  if (!b.ok()) return Named(b.status(), /*always=*/true);
  return b;
}

StatusOr<regress::Baseline> Backend::GetBaseline(const std::string& name, int version) {
  VB_BACKEND_READY();
  VB_RETURN_IF_ERROR(RecordsKept());
  auto b = c_->GetBaseline(name, version);
  if (!b.ok()) return Named(b.status(), /*always=*/true);
  return b;
}

StatusOr<std::vector<regress::Baseline>> Backend::ListBaselines() {
  VB_BACKEND_READY();
  VB_RETURN_IF_ERROR(RecordsKept());
  auto list = c_->ListBaselines();
  if (!list.ok()) return Named(list.status(), /*always=*/true);
  return list;
}

StatusOr<std::int64_t> Backend::SaveRegression(const regress::RegressResult& result) {
  VB_BACKEND_READY();
  VB_RETURN_IF_ERROR(RecordsKept());
  auto id = c_->SaveRegression(result);
  if (!id.ok()) return Named(id.status(), /*always=*/true);
  return id;
}

StatusOr<v1::Regression> Backend::GetRegression(std::int64_t id) {
  VB_BACKEND_READY();
  VB_RETURN_IF_ERROR(RecordsKept());
  auto r = c_->GetRegression(id);
  if (!r.ok()) return Named(r.status(), /*always=*/true);
  return r;
}

StatusOr<v1::DescribeStoreResponse> Backend::DescribeStore() {
  VB_BACKEND_READY();
  auto d = c_->DescribeStore();
  if (!d.ok()) return Named(d.status(), /*always=*/true);
  return d;
}

#undef VB_BACKEND_READY

StatusOr<experiment::Comparison> RemoteComparison(client::Client& client, std::int64_t batch,
                                                  const std::vector<std::int64_t>& run_ids) {
  auto cmp = client.Compare(batch, run_ids);
  if (!cmp.ok()) return cmp.status();
  return experiment::ComparisonFromProto(*cmp);
}

std::unique_ptr<Backend> ChooseBackend(const std::string& server, const std::string& store_path,
                                       const std::function<std::unique_ptr<client::Client>()>& make_client,
                                       LocalUse use) {
  if (!server.empty()) return std::make_unique<Backend>(make_client(), "server " + server);
  server::LocalServiceOptions o;
  o.store = store_path;
  o.execute = use.execute;
  o.keep_traces = use.keep_traces;
  auto local = server::LocalService::Start(std::move(o));
  if (!local.ok()) return std::make_unique<Backend>(local.status(), server::LocalService::Describe(store_path));
  client::ClientOptions copts;
  copts.address = (*local)->Where();
  copts.token = (*local)->token();
  copts.deadline_s = 300.0;  // in process: a slow call is a big store, not a lost network
  auto c = std::make_unique<client::Client>((*local)->InProcessChannel(), copts);
  std::string name = (*local)->Where();
  return std::make_unique<Backend>(std::move(c), std::move(name), std::move(local.value()));
}

}  // namespace vb::benchctl
