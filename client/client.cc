#include "client/client.h"

#include <algorithm>

#include <grpcpp/grpcpp.h>

#include "client/trace_stream.h"

namespace vb::client {

namespace v1 = valvebench::v1;

Status FromGrpc(const grpc::Status& st) {
  if (st.ok()) return Status::Ok();
  const std::string& m = st.error_message();
  switch (st.error_code()) {
    case grpc::StatusCode::INVALID_ARGUMENT: return Status::InvalidArgument(m);
    case grpc::StatusCode::NOT_FOUND: return Status::NotFound(m);
    case grpc::StatusCode::ALREADY_EXISTS: return Status::AlreadyExists(m);
    case grpc::StatusCode::FAILED_PRECONDITION: return Status::FailedPrecondition(m);
    case grpc::StatusCode::OUT_OF_RANGE: return Status::OutOfRange(m);
    case grpc::StatusCode::RESOURCE_EXHAUSTED: return Status::ResourceExhausted(m);
    case grpc::StatusCode::UNAUTHENTICATED: return Status::FailedPrecondition("not authenticated: " + m);
    case grpc::StatusCode::PERMISSION_DENIED: return Status::FailedPrecondition("permission denied: " + m);
    case grpc::StatusCode::UNAVAILABLE: return Status::Unavailable("server unavailable: " + m);
    case grpc::StatusCode::DEADLINE_EXCEEDED: return Status::Unavailable("deadline exceeded: " + m);
    case grpc::StatusCode::CANCELLED: return Status::Aborted(m);
    case grpc::StatusCode::DATA_LOSS: return Status::DataLoss(m);
    default: return Status::Internal(m);
  }
}

Status Client::Error(const grpc::Status& st) const {
  switch (st.error_code()) {
    case grpc::StatusCode::UNAVAILABLE:
    case grpc::StatusCode::DEADLINE_EXCEEDED:
      // Never connected: one line that says where we looked and how to point elsewhere, not gRPC's resolver
      // and socket trace. A server that answered UNAVAILABLE itself keeps its message.
      if (channel_->GetState(false) != GRPC_CHANNEL_READY)
        return Status::Unavailable("cannot reach valvebench-server at " + opt_.address +
                                   " (is it running? the address comes from --server or VALVEBENCH_SERVER)");
      break;
    case grpc::StatusCode::UNAUTHENTICATED:
      if (call_.authorization ? call_.authorization->empty() : opt_.token.empty())
        return Status::FailedPrecondition("not authenticated: no token given; the server at " + opt_.address +
                                          " needs one: set VALVEBENCH_TOKEN or pass --token TOKEN");
      return Status::FailedPrecondition("not authenticated: " + st.error_message() +
                                        " (the token comes from --token or VALVEBENCH_TOKEN)");
    default:
      break;
  }
  return FromGrpc(st);
}

Client::Client(const ClientOptions& options) : opt_(options) {
  std::shared_ptr<grpc::ChannelCredentials> creds;
  if (!opt_.tls_ca_pem.empty()) {
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = opt_.tls_ca_pem;
    creds = grpc::SslCredentials(ssl);
  } else {
    creds = grpc::InsecureChannelCredentials();
  }
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(64 << 20);
  args.SetMaxSendMessageSize(64 << 20);
  channel_ = grpc::CreateCustomChannel(opt_.address, creds, args);
  stub_ = v1::BenchService::NewStub(channel_);
}

Client::Client(std::shared_ptr<grpc::Channel> channel, const ClientOptions& options)
    : opt_(options), channel_(std::move(channel)), stub_(v1::BenchService::NewStub(channel_)) {}

Client Client::With(const CallOptions& call) const {
  Client view(*this);
  view.call_ = call;
  return view;
}

void Client::Prepare(grpc::ClientContext* ctx, double deadline_s) const {
  if (call_.deadline_s > 0.0) deadline_s = call_.deadline_s;
  ctx->set_deadline(std::chrono::system_clock::now() +
                    std::chrono::microseconds(static_cast<std::int64_t>(deadline_s * 1e6)));
  if (call_.authorization) {
    if (!call_.authorization->empty()) ctx->AddMetadata("authorization", *call_.authorization);
  } else if (!opt_.token.empty()) {
    ctx->AddMetadata("authorization", "Bearer " + opt_.token);
  }
  Keep(grpc::Status::OK);  // a call starts with nothing to report
}

void Client::Keep(const grpc::Status& st) const {
  if (call_.rpc_status != nullptr) *call_.rpc_status = st;
}

Status Client::Fail(const grpc::Status& st) const {
  Keep(st);
  return Error(st);
}

StatusOr<v1::SubmitRunResponse> Client::Submit(const v1::ExperimentSpec& spec, const std::string& batch_name) {
  grpc::ClientContext ctx;
  Prepare(&ctx, opt_.deadline_s);
  v1::SubmitRunRequest req;
  *req.mutable_spec() = spec;
  req.set_batch_name(batch_name);
  v1::SubmitRunResponse resp;
  auto st = stub_->SubmitRun(&ctx, req, &resp);
  if (!st.ok()) return Fail(st);
  return resp;
}

StatusOr<v1::SubmitRunResponse> Client::SubmitBatch(const std::vector<v1::ExperimentSpec>& specs,
                                                   const std::string& batch_name,
                                                   const std::vector<v1::RunKey>& keys) {
  grpc::ClientContext ctx;
  Prepare(&ctx, opt_.deadline_s);
  v1::SubmitBatchRequest req;
  for (const auto& s : specs) *req.add_specs() = s;
  for (const auto& k : keys) *req.add_keys() = k;
  req.set_batch_name(batch_name);
  v1::SubmitRunResponse resp;
  auto st = stub_->SubmitBatch(&ctx, req, &resp);
  if (!st.ok()) return Fail(st);
  return resp;
}

StatusOr<v1::Run> Client::GetRun(std::int64_t run_id) {
  grpc::ClientContext ctx;
  Prepare(&ctx, opt_.deadline_s);
  v1::GetRunRequest req;
  req.set_run_id(run_id);
  v1::Run resp;
  auto st = stub_->GetRun(&ctx, req, &resp);
  if (!st.ok()) return Fail(st);
  return resp;
}

StatusOr<v1::ListRunsResponse> Client::ListRuns(const v1::ListRunsRequest& request) {
  grpc::ClientContext ctx;
  Prepare(&ctx, opt_.deadline_s);
  v1::ListRunsResponse resp;
  auto st = stub_->ListRuns(&ctx, request, &resp);
  if (!st.ok()) return Fail(st);
  return resp;
}

StatusOr<v1::Run> Client::Cancel(std::int64_t run_id, const std::string& reason) {
  grpc::ClientContext ctx;
  Prepare(&ctx, opt_.deadline_s);
  v1::CancelRunRequest req;
  req.set_run_id(run_id);
  req.set_reason(reason);
  v1::Run resp;
  auto st = stub_->CancelRun(&ctx, req, &resp);
  if (!st.ok()) return Fail(st);
  return resp;
}

Status Client::Watch(std::int64_t run_id, double deadline_s, double sample_rate_Hz,
                     const std::function<bool(const v1::RunEvent&)>& on_event) {
  grpc::ClientContext ctx;
  Prepare(&ctx, deadline_s);
  v1::WatchRunRequest req;
  req.set_run_id(run_id);
  req.set_sample_rate_hz(sample_rate_Hz);
  auto reader = stub_->WatchRun(&ctx, req);
  v1::RunEvent ev;
  while (reader->Read(&ev)) {
    if (!on_event(ev)) {
      ctx.TryCancel();
      break;
    }
  }
  auto st = reader->Finish();
  if (st.error_code() == grpc::StatusCode::CANCELLED) return Status::Ok();  // ours: on_event said enough
  return Fail(st);
}

StatusOr<FetchedTrace> Client::GetTrace(std::int64_t run_id, double deadline_s) {
  v1::GetTraceRequest req;
  req.set_run_id(run_id);
  return GetTrace(req, deadline_s);
}

StatusOr<FetchedTrace> Client::GetTrace(const v1::GetTraceRequest& request, double deadline_s) {
  auto stream = OpenTrace(request, deadline_s);
  if (!stream.ok()) return stream.status();
  while ((*stream)->Next()) {
  }
  if (!(*stream)->status().ok()) return (*stream)->status();
  return (*stream)->TakeAll();
}

StatusOr<std::unique_ptr<TraceStream>> Client::OpenTrace(const v1::GetTraceRequest& request, double deadline_s) {
  std::unique_ptr<TraceStream> stream(new TraceStream(*this));
  Prepare(&stream->ctx_, deadline_s);
  stream->reader_ = stub_->GetTrace(&stream->ctx_, request);
  if (Status st = stream->ReadChunk(); !st.ok()) return st;
  return stream;
}

StatusOr<v1::CompareRunsResponse> Client::Compare(std::int64_t batch_id, const std::vector<std::int64_t>& run_ids) {
  grpc::ClientContext ctx;
  Prepare(&ctx, opt_.deadline_s);
  v1::CompareRunsRequest req;
  req.set_batch_id(batch_id);
  for (auto id : run_ids) req.add_run_ids(id);
  v1::CompareRunsResponse resp;
  auto st = stub_->CompareRuns(&ctx, req, &resp);
  if (!st.ok()) return Fail(st);
  return resp;
}

StatusOr<v1::ListNightsResponse> Client::ListNights(int limit) {
  grpc::ClientContext ctx;
  Prepare(&ctx, opt_.deadline_s);
  v1::ListNightsRequest req;
  req.set_limit(limit);
  v1::ListNightsResponse resp;
  auto st = stub_->ListNights(&ctx, req, &resp);
  if (!st.ok()) return Fail(st);
  return resp;
}

StatusOr<v1::GetBenchHealthResponse> Client::GetBenchHealth(const std::string& bench) {
  grpc::ClientContext ctx;
  Prepare(&ctx, opt_.deadline_s);
  v1::GetBenchHealthRequest req;
  req.set_bench(bench);
  v1::GetBenchHealthResponse resp;
  auto st = stub_->GetBenchHealth(&ctx, req, &resp);
  if (!st.ok()) return Fail(st);
  return resp;
}

StatusOr<v1::ListBenchesResponse> Client::Benches() {
  grpc::ClientContext ctx;
  Prepare(&ctx, opt_.deadline_s);
  v1::ListBenchesResponse resp;
  auto st = stub_->ListBenches(&ctx, v1::ListBenchesRequest{}, &resp);
  if (!st.ok()) return Fail(st);
  return resp;
}

StatusOr<v1::GetQueueResponse> Client::GetQueue() {
  grpc::ClientContext ctx;
  Prepare(&ctx, opt_.deadline_s);
  v1::GetQueueResponse resp;
  auto st = stub_->GetQueue(&ctx, v1::GetQueueRequest{}, &resp);
  if (!st.ok()) return Fail(st);
  return resp;
}

StatusOr<v1::DiagnoseRunsResponse> Client::DiagnoseRuns(const std::vector<std::int64_t>& run_ids,
                                                        const std::string& model, double deadline_s) {
  v1::DiagnoseRunsRequest req;
  for (std::int64_t id : run_ids) req.add_run_ids(id);
  req.set_model(model);
  return DiagnoseRuns(req, deadline_s);
}

StatusOr<v1::DiagnoseRunsResponse> Client::DiagnoseRuns(const v1::DiagnoseRunsRequest& request, double deadline_s) {
  grpc::ClientContext ctx;
  Prepare(&ctx, deadline_s);
  v1::DiagnoseRunsResponse resp;
  auto st = stub_->DiagnoseRuns(&ctx, request, &resp);
  if (!st.ok()) return Fail(st);
  return resp;
}

StatusOr<v1::SubmitRunResponse> Client::ImportRuns(const v1::ImportRunsRequest& request, double deadline_s) {
  // A request that fits one message goes as one (the server checks all of it before storing anything);
  // a larger one is streamed (ImportRunsStream): the header with every run's metadata, then the samples in
  // parts of kPartSamples, so a run of any length fits gRPC's message limit and the server stores it chunk by
  // chunk.
  constexpr std::size_t kOneMessageBytes = 16 << 20;
  constexpr int kPartSamples = 65536;
  grpc::ClientContext ctx;
  Prepare(&ctx, deadline_s);
  v1::SubmitRunResponse resp;
  if (request.ByteSizeLong() < kOneMessageBytes) {
    auto st = stub_->ImportRuns(&ctx, request, &resp);
    if (!st.ok()) return Fail(st);
    return resp;
  }
  auto writer = stub_->ImportRunsStream(&ctx, &resp);
  v1::ImportRunsPart part;
  v1::ImportRunsRequest* header = part.mutable_header();
  header->set_dataset(request.dataset());
  header->set_model(request.model());
  header->set_description(request.description());
  for (const auto& r : request.runs()) {
    v1::ImportedRun* meta = header->add_runs();
    meta->set_id(r.id());
    meta->set_supply_v(r.supply_v());
    meta->set_supply_pressure_pa(r.supply_pressure_pa());
    meta->set_t_start_s(r.t_start_s());
    meta->set_split(r.split());
    meta->set_sample_period_s(r.sample_period_s());
    meta->set_samples(r.gate_size());
    meta->set_has_x_m(r.x_m_size() > 0);
    meta->set_has_v_coil_v(r.v_coil_v_size() > 0);
  }
  bool open = writer->Write(part);
  for (int k = 0; open && k < request.runs_size(); ++k) {
    const auto& r = request.runs(k);
    // Each column is sent as it is, ragged or not: the server names a column that does not match.
    const int longest = std::max({r.gate_size(), r.i_a_size(), r.x_m_size(), r.v_coil_v_size()});
    auto slice = [](const auto& column, auto* out, int from, int to) {
      if (from < column.size()) out->Add(column.begin() + from, column.begin() + std::min(to, column.size()));
    };
    for (int from = 0; open && from < longest; from += kPartSamples) {
      const int to = from + kPartSamples;
      v1::ImportSamples* s = part.mutable_samples();
      s->Clear();
      s->set_run_index(k);
      slice(r.gate(), s->mutable_gate(), from, to);
      slice(r.i_a(), s->mutable_i_a(), from, to);
      slice(r.x_m(), s->mutable_x_m(), from, to);
      slice(r.v_coil_v(), s->mutable_v_coil_v(), from, to);
      open = writer->Write(part);
    }
  }
  if (open) writer->WritesDone();
  auto st = writer->Finish();
  if (!st.ok()) return Fail(st);
  return resp;
}

StatusOr<v1::PruneRunsResponse> Client::PruneRuns(const v1::PruneRunsRequest& request, double deadline_s) {
  grpc::ClientContext ctx;
  Prepare(&ctx, deadline_s);
  v1::PruneRunsResponse resp;
  auto st = stub_->PruneRuns(&ctx, request, &resp);
  if (!st.ok()) return Fail(st);
  return resp;
}

namespace {

regress::Baseline FromProto(const v1::Baseline& p) {
  regress::Baseline b;
  b.name = p.name();
  b.version = p.version();
  b.created_unix_s = p.created_unix_s();
  b.source = p.source();
  b.note = p.note();
  for (const v1::BaselineEntry& e : p.entries()) b.cases[e.case_name()][e.metric()] = {e.mean(), e.spread(), e.n()};
  return b;
}

}  // namespace

StatusOr<regress::Baseline> Client::SaveBaseline(const regress::Baseline& b) {
  v1::SaveBaselineRequest req;
  v1::Baseline* p = req.mutable_baseline();
  p->set_name(b.name);
  p->set_source(b.source);
  p->set_note(b.note);
  for (const auto& [c, metrics] : b.cases)
    for (const auto& [metric, s] : metrics) {
      if (s.n <= 0) continue;  // no finite value in any repeat: nothing to hold a later run against
      v1::BaselineEntry* e = p->add_entries();
      e->set_case_name(c);
      e->set_metric(metric);
      e->set_mean(s.mean);
      e->set_spread(s.spread);
      e->set_n(s.n);
    }
  grpc::ClientContext ctx;
  Prepare(&ctx, opt_.deadline_s);
  v1::Baseline resp;
  auto st = stub_->SaveBaseline(&ctx, req, &resp);
  if (!st.ok()) return Fail(st);
  return FromProto(resp);
}

StatusOr<regress::Baseline> Client::GetBaseline(const std::string& name, int version) {
  v1::GetBaselineRequest req;
  req.set_name(name);
  req.set_version(version);
  grpc::ClientContext ctx;
  Prepare(&ctx, opt_.deadline_s);
  v1::Baseline resp;
  auto st = stub_->GetBaseline(&ctx, req, &resp);
  if (!st.ok()) return Fail(st);
  return FromProto(resp);
}

StatusOr<std::vector<regress::Baseline>> Client::ListBaselines() {
  grpc::ClientContext ctx;
  Prepare(&ctx, opt_.deadline_s);
  v1::ListBaselinesResponse resp;
  auto st = stub_->ListBaselines(&ctx, v1::ListBaselinesRequest{}, &resp);
  if (!st.ok()) return Fail(st);
  std::vector<regress::Baseline> out;
  out.reserve(resp.baselines_size());
  for (const v1::Baseline& b : resp.baselines()) out.push_back(FromProto(b));
  return out;
}

StatusOr<std::int64_t> Client::SaveRegression(const regress::RegressResult& result) {
  v1::SaveRegressionRequest req;
  req.set_result_json(regress::ResultToJson(result).dump());
  grpc::ClientContext ctx;
  Prepare(&ctx, opt_.deadline_s);
  v1::SaveRegressionResponse resp;
  auto st = stub_->SaveRegression(&ctx, req, &resp);
  if (!st.ok()) return Fail(st);
  return resp.id();
}

StatusOr<v1::Regression> Client::GetRegression(std::int64_t id) {
  v1::GetRegressionRequest req;
  req.set_id(id);
  grpc::ClientContext ctx;
  Prepare(&ctx, opt_.deadline_s);
  v1::Regression resp;
  auto st = stub_->GetRegression(&ctx, req, &resp);
  if (!st.ok()) return Fail(st);
  return resp;
}

StatusOr<v1::DescribeStoreResponse> Client::DescribeStore() {
  grpc::ClientContext ctx;
  Prepare(&ctx, opt_.deadline_s);
  v1::DescribeStoreResponse resp;
  auto st = stub_->DescribeStore(&ctx, v1::DescribeStoreRequest{}, &resp);
  if (!st.ok()) return Fail(st);
  return resp;
}

}  // namespace vb::client
