// A small C++ client over the BenchService stub: a deadline on every call, the bearer token on every call,
// gRPC status mapped back to vb::Status (the message keeps the server's field path).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/status.h"
#include "common/trace_columns.h"
#include "regress/compare.h"
#include "valvebench/v1/api.grpc.pb.h"

namespace vb::client {

struct ClientOptions {
  std::string address = "127.0.0.1:50051";
  std::string token;                    // bearer token
  std::string tls_ca_pem;               // non-empty: TLS with this CA (PEM contents)
  double deadline_s = 30.0;             // unary calls
};

// A trace fetched back: columns by channel name, decoded by the one decoder (common/trace_columns.h).
using FetchedTrace = vb::TraceColumns;

// Whose credentials and how long, per call: a door that serves many callers over one channel (the web gateway)
// takes a view of its Client per request (Client::With), so every caller's own token goes with its calls.
struct CallOptions {
  // The "authorization" metadata as the caller sent it ("Bearer <token>"); "" = none at all (the service then
  // answers UNAUTHENTICATED); unset = the Client's ClientOptions::token.
  std::optional<std::string> authorization;
  // > 0: every call of the view; 0: each method's own (ClientOptions::deadline_s or its deadline_s argument).
  double deadline_s = 0.0;
  // Where each call of the view leaves its status as the service answered it, code and message untouched, for a
  // door that maps gRPC codes onto its own (HTTP statuses) where vb::Status has none (UNAUTHENTICATED,
  // PERMISSION_DENIED). OK when the call succeeded or the error is the client's own (a trace that does not
  // decode: the returned vb::Status says it). nullptr: not kept.
  grpc::Status* rpc_status = nullptr;
};

class TraceStream;

class Client {
 public:
  explicit Client(const ClientOptions& options);
  // Over a channel made elsewhere: a local service's in-process channel (service/local_service.h). The options'
  // address only names it in messages; tls_ca_pem is not used.
  Client(std::shared_ptr<grpc::Channel> channel, const ClientOptions& options);
  // A view over the same channel and stub with per-call credentials and deadline (cheap: two shared pointers
  // and the options). Thread-safe to take from a shared const Client; use each view from one thread.
  Client With(const CallOptions& call) const;

  StatusOr<valvebench::v1::SubmitRunResponse> Submit(const valvebench::v1::ExperimentSpec& spec,
                                                     const std::string& batch_name = "");
  // Several specs as one batch (all queued or none); keys: empty, or one per already expanded spec.
  StatusOr<valvebench::v1::SubmitRunResponse> SubmitBatch(const std::vector<valvebench::v1::ExperimentSpec>& specs,
                                                          const std::string& batch_name = "",
                                                          const std::vector<valvebench::v1::RunKey>& keys = {});
  StatusOr<valvebench::v1::Run> GetRun(std::int64_t run_id);
  StatusOr<valvebench::v1::ListRunsResponse> ListRuns(const valvebench::v1::ListRunsRequest& request);
  StatusOr<valvebench::v1::Run> Cancel(std::int64_t run_id, const std::string& reason = "");
  // Calls on_event for every event until the run ends, on_event returns false, or deadline_s passes.
  Status Watch(std::int64_t run_id, double deadline_s, double sample_rate_Hz,
               const std::function<bool(const valvebench::v1::RunEvent&)>& on_event);
  StatusOr<FetchedTrace> GetTrace(std::int64_t run_id, double deadline_s = 60.0);
  // A window and/or a min/max decimation done by the server (request.max_points, from_s, to_s: api.proto).
  StatusOr<FetchedTrace> GetTrace(const valvebench::v1::GetTraceRequest& request, double deadline_s = 60.0);
  // The same read chunk by chunk, for a trace too long to hold (client/trace_stream.h): the first chunk is read
  // here, so a refusal (token, role, no such run) is this call's error.
  StatusOr<std::unique_ptr<TraceStream>> OpenTrace(const valvebench::v1::GetTraceRequest& request,
                                                   double deadline_s = 3600.0);
  StatusOr<valvebench::v1::CompareRunsResponse> Compare(std::int64_t batch_id, const std::vector<std::int64_t>& run_ids);
  StatusOr<valvebench::v1::ListBenchesResponse> Benches();
  // The running runs and the queue with positions and ETAs, and the benches the estimate is over.
  StatusOr<valvebench::v1::GetQueueResponse> GetQueue();
  StatusOr<valvebench::v1::ListNightsResponse> ListNights(int limit);
  // The bench twin's tracking of `bench` ("" = every checked bench), from the server's nights.
  StatusOr<valvebench::v1::GetBenchHealthResponse> GetBenchHealth(const std::string& bench);
  // The gap diagnosis of stored runs, computed by the server (seconds to a minute).
  StatusOr<valvebench::v1::DiagnoseRunsResponse> DiagnoseRuns(const std::vector<std::int64_t>& run_ids,
                                                              const std::string& model = "", double deadline_s = 300.0);
  // The same with every field of the request (a model file's ModelSpec, the next runs suggested).
  StatusOr<valvebench::v1::DiagnoseRunsResponse> DiagnoseRuns(const valvebench::v1::DiagnoseRunsRequest& request,
                                                              double deadline_s = 300.0);
  StatusOr<valvebench::v1::SubmitRunResponse> ImportRuns(const valvebench::v1::ImportRunsRequest& request,
                                                         double deadline_s = 300.0);

  // PruneRuns (admin): old finished runs deleted by the service's rules (docs/store.md, "Retention"); a large
  // delete takes a while, hence its own deadline.
  StatusOr<valvebench::v1::PruneRunsResponse> PruneRuns(const valvebench::v1::PruneRunsRequest& request,
                                                        double deadline_s = 600.0);

  // Baselines and regression results in the service's store (docs/regress.md): a server's for the lab's shared
  // history, the local service's for benchctl --local. Errors are the service's, naming the field or the record
  // ("baseline.entries[2].spread: ...", "baseline 'main' has no version 9", "regression 7 not found").
  //
  // Stores the cases' statistics with n > 0 under b.name as its next version (b.version is ignored); returns
  // the baseline as stored (its version and time).
  StatusOr<regress::Baseline> SaveBaseline(const regress::Baseline& b);
  // version 0 = the newest.
  StatusOr<regress::Baseline> GetBaseline(const std::string& name, int version = 0);
  // Every version of every baseline, without their cases.
  StatusOr<std::vector<regress::Baseline>> ListBaselines();
  // Keeps a regression result (its batch_id: a batch of the service's store, or 0); returns its id.
  StatusOr<std::int64_t> SaveRegression(const regress::RegressResult& result);
  // A stored result (a client's or a scheduled night's) with its whole JSON.
  StatusOr<valvebench::v1::Regression> GetRegression(std::int64_t id);
  // The service's store as a whole: engine, location, schema version, counts (benchctl db info).
  StatusOr<valvebench::v1::DescribeStoreResponse> DescribeStore();

 private:
  friend class TraceStream;
  void Prepare(grpc::ClientContext* ctx, double deadline_s) const;
  // Error(st), with st kept in call_.rpc_status (Keep).
  Status Fail(const grpc::Status& st) const;
  void Keep(const grpc::Status& st) const;
  // FromGrpc, plus what to do next where the client knows better than the server: a server that cannot be
  // reached (the address, --server/VALVEBENCH_SERVER) and a missing token (--token/VALVEBENCH_TOKEN).
  Status Error(const grpc::Status& st) const;
  ClientOptions opt_;
  CallOptions call_;
  std::shared_ptr<grpc::Channel> channel_;
  std::shared_ptr<valvebench::v1::BenchService::Stub> stub_;
};

// gRPC status -> vb::Status: INVALID_ARGUMENT, NOT_FOUND, FAILED_PRECONDITION, RESOURCE_EXHAUSTED keep their
// meaning; UNAUTHENTICATED/PERMISSION_DENIED become FailedPrecondition with "permission: ..."; UNAVAILABLE and
// DEADLINE_EXCEEDED become Unavailable.
Status FromGrpc(const grpc::Status& st);

}  // namespace vb::client
