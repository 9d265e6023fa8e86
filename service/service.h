// The BenchService implementation: a thin layer over the store, the workers and the experiment core.
// Every handler asks the call gate for its caller first (service/authorization.h), maps core errors through
// ToGrpcStatus, and never lets an exception out.
#pragma once

#include <chrono>
#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "db/store.h"
#include "service/authorization.h"
#include "service/settings.h"
#include "runs/admit.h"
#include "runs/monitor.h"
#include "runs/worker.h"
#include "valvebench/v1/api.grpc.pb.h"

namespace vb::server {

// Store connections for handler threads (a Store is single-threaded; SQLite WAL lets them run side by side).
// Bounded (issue 34: 1,000 live streams left 1,650 SQLite connections, 3,315 open files, until restart): at
// most kMaxOpen connections at once (an Acquire beyond waits up to kAcquireWait_s for one to come back, then
// UNAVAILABLE); at most kMaxIdle kept for reuse, and an idle one older than kIdle_s is closed. The stream caps
// (StreamGate, 96 in all) stay below kMaxOpen so that unary calls always find a connection.
class StorePool {
 public:
  static constexpr int kMaxOpen = 128;
  static constexpr int kMaxIdle = 8;
  static constexpr double kIdle_s = 30.0;
  static constexpr double kAcquireWait_s = 5.0;
  explicit StorePool(std::string path) : path_(std::move(path)) {}
  class Handle {
   public:
    Handle(StorePool* pool, std::unique_ptr<db::Store> s) : pool_(pool), store_(std::move(s)) {}
    Handle(Handle&&) = default;
    ~Handle();
    db::Store* operator->() { return store_.get(); }
    db::Store* get() { return store_.get(); }

   private:
    StorePool* pool_;
    std::unique_ptr<db::Store> store_;
  };
  StatusOr<Handle> Acquire();
  // Connections open now (in use and idle), and idle ones, for the tests and the log.
  int open() const;
  int idle() const;
  // What its connections open: a SQLite file or a PostgreSQL connection string (DescribeStore).
  const std::string& location() const { return path_; }

 private:
  friend class Handle;
  using Clock = std::chrono::steady_clock;
  struct Idle {
    std::unique_ptr<db::Store> store;
    Clock::time_point since;
  };
  void Release(std::unique_ptr<db::Store> s);
  void CloseStale(std::vector<std::unique_ptr<db::Store>>* out);  // with mu_ held: moves stale ones out
  std::string path_;
  mutable std::mutex mu_;
  std::condition_variable returned_;
  std::vector<Idle> free_;
  int open_ = 0;
};

// Concurrent server streams (WatchRun, GetTrace), per user and in all: each holds a gRPC thread and a store
// connection for its whole life (issue 34: 1,000 viewer WatchRun streams, 913 threads, +1.3 GB). A stream
// beyond a cap is refused with RESOURCE_EXHAUSTED naming the cap. Per user 64: the web dashboard's 48 live
// views in all (GatewayOptions::max_streams, each its token's user's stream here) and its chart requests.
class StreamGate {
 public:
  static constexpr int kMaxPerUser = 64;
  static constexpr int kMax = 96;
  // A place, or null with `why` set.
  std::shared_ptr<void> Take(const std::string& user, const char* call, std::string* why);
  int open() const;

 private:
  mutable std::mutex mu_;
  int total_ = 0;
  std::map<std::string, int> per_user_;
};

class BenchServiceImpl final : public valvebench::v1::BenchService::Service {
 public:
  BenchServiceImpl(const ServiceSettings* settings, StorePool* pool, runs::Registry* registry,
                   const std::vector<std::unique_ptr<runs::Worker>>* workers)
      : settings_(settings),
        policy_(settings->AdmitPolicy()),
        pool_(pool),
        registry_(registry),
        workers_(workers),
        gate_(&settings->auth) {}

  grpc::Status SubmitRun(grpc::ServerContext* ctx, const valvebench::v1::SubmitRunRequest* req,
                         valvebench::v1::SubmitRunResponse* resp) override;
  grpc::Status SubmitBatch(grpc::ServerContext* ctx, const valvebench::v1::SubmitBatchRequest* req,
                           valvebench::v1::SubmitRunResponse* resp) override;
  grpc::Status GetRun(grpc::ServerContext* ctx, const valvebench::v1::GetRunRequest* req,
                      valvebench::v1::Run* resp) override;
  grpc::Status ListRuns(grpc::ServerContext* ctx, const valvebench::v1::ListRunsRequest* req,
                        valvebench::v1::ListRunsResponse* resp) override;
  grpc::Status CancelRun(grpc::ServerContext* ctx, const valvebench::v1::CancelRunRequest* req,
                         valvebench::v1::Run* resp) override;
  grpc::Status WatchRun(grpc::ServerContext* ctx, const valvebench::v1::WatchRunRequest* req,
                        grpc::ServerWriter<valvebench::v1::RunEvent>* writer) override;
  grpc::Status GetTrace(grpc::ServerContext* ctx, const valvebench::v1::GetTraceRequest* req,
                        grpc::ServerWriter<valvebench::v1::TraceChunk>* writer) override;
  grpc::Status CompareRuns(grpc::ServerContext* ctx, const valvebench::v1::CompareRunsRequest* req,
                           valvebench::v1::CompareRunsResponse* resp) override;
  grpc::Status ListBenches(grpc::ServerContext* ctx, const valvebench::v1::ListBenchesRequest* req,
                           valvebench::v1::ListBenchesResponse* resp) override;
  // service/import.cc
  grpc::Status ImportRuns(grpc::ServerContext* ctx, const valvebench::v1::ImportRunsRequest* req,
                          valvebench::v1::SubmitRunResponse* resp) override;
  grpc::Status ImportRunsStream(grpc::ServerContext* ctx, grpc::ServerReader<valvebench::v1::ImportRunsPart>* reader,
                                valvebench::v1::SubmitRunResponse* resp) override;
  // service/diagnose_service.cc
  grpc::Status DiagnoseRuns(grpc::ServerContext* ctx, const valvebench::v1::DiagnoseRunsRequest* req,
                            valvebench::v1::DiagnoseRunsResponse* resp) override;
  // service/nights_service.cc
  grpc::Status ListNights(grpc::ServerContext* ctx, const valvebench::v1::ListNightsRequest* req,
                          valvebench::v1::ListNightsResponse* resp) override;
  // service/bench_health.cc
  grpc::Status GetBenchHealth(grpc::ServerContext* ctx, const valvebench::v1::GetBenchHealthRequest* req,
                              valvebench::v1::GetBenchHealthResponse* resp) override;
  // service/prune_service.cc
  grpc::Status PruneRuns(grpc::ServerContext* ctx, const valvebench::v1::PruneRunsRequest* req,
                         valvebench::v1::PruneRunsResponse* resp) override;
  // service/queue_service.cc
  grpc::Status GetQueue(grpc::ServerContext* ctx, const valvebench::v1::GetQueueRequest* req,
                        valvebench::v1::GetQueueResponse* resp) override;
  // service/records_service.cc: baselines, regression results, the store as a whole
  grpc::Status SaveBaseline(grpc::ServerContext* ctx, const valvebench::v1::SaveBaselineRequest* req,
                            valvebench::v1::Baseline* resp) override;
  grpc::Status GetBaseline(grpc::ServerContext* ctx, const valvebench::v1::GetBaselineRequest* req,
                           valvebench::v1::Baseline* resp) override;
  grpc::Status ListBaselines(grpc::ServerContext* ctx, const valvebench::v1::ListBaselinesRequest* req,
                             valvebench::v1::ListBaselinesResponse* resp) override;
  grpc::Status SaveRegression(grpc::ServerContext* ctx, const valvebench::v1::SaveRegressionRequest* req,
                              valvebench::v1::SaveRegressionResponse* resp) override;
  grpc::Status GetRegression(grpc::ServerContext* ctx, const valvebench::v1::GetRegressionRequest* req,
                             valvebench::v1::Regression* resp) override;
  grpc::Status DescribeStore(grpc::ServerContext* ctx, const valvebench::v1::DescribeStoreRequest* req,
                             valvebench::v1::DescribeStoreResponse* resp) override;

  // Admits and queues a submission (runs::Admit, runs::Enqueue) and wakes the workers: what SubmitRun and
  // SubmitBatch do after authorising, and what the nights scheduler calls directly.
  StatusOr<runs::Queued> Queue(const runs::Submission& submission);

  // Who may call what (service/authorization.h): HostService installs its interceptor; each handler's first step
  // is gate_.Caller(ctx, &who).
  CallGate* gate() { return &gate_; }

 private:
  grpc::Status Submit(const runs::Submission& submission, valvebench::v1::SubmitRunResponse* resp);
  grpc::Status FillRun(db::Store* store, const db::RunRecord& r, bool full, valvebench::v1::Run* out);
  grpc::Status LabBenches(valvebench::v1::ListBenchesResponse* resp);

  const ServiceSettings* settings_;
  const runs::Policy policy_;
  StorePool* pool_;
  runs::Registry* registry_;
  const std::vector<std::unique_ptr<runs::Worker>>* workers_;
  StreamGate streams_;
  CallGate gate_;
};



}  // namespace vb::server
