// The BenchService implementation: a thin layer over the store, the workers and the experiment core.
// Every handler authenticates first, maps core errors through ToGrpcStatus, and never lets an exception out.
#pragma once

#include <memory>
#include <mutex>
#include <vector>

#include "db/store.h"
#include "service/settings.h"
#include "runs/admit.h"
#include "runs/monitor.h"
#include "runs/worker.h"
#include "valvebench/v1/api.grpc.pb.h"

namespace vb::server {

// Store connections for handler threads (a Store is single-threaded; SQLite WAL lets them run side by side).
class StorePool {
 public:
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

 private:
  friend class Handle;
  std::string path_;
  std::mutex mu_;
  std::vector<std::unique_ptr<db::Store>> free_;
};

class BenchServiceImpl final : public valvebench::v1::BenchService::Service {
 public:
  BenchServiceImpl(const ServiceSettings* settings, StorePool* pool, runs::Registry* registry,
                   const std::vector<std::unique_ptr<runs::Worker>>* workers)
      : settings_(settings), policy_(settings->AdmitPolicy()), pool_(pool), registry_(registry), workers_(workers) {}

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
  // service/prune_service.cc
  grpc::Status PruneRuns(grpc::ServerContext* ctx, const valvebench::v1::PruneRunsRequest* req,
                         valvebench::v1::PruneRunsResponse* resp) override;
  // service/queue_service.cc
  grpc::Status GetQueue(grpc::ServerContext* ctx, const valvebench::v1::GetQueueRequest* req,
                        valvebench::v1::GetQueueResponse* resp) override;

  // Admits and queues a submission (runs::Admit, runs::Enqueue) and wakes the workers: what SubmitRun and
  // SubmitBatch do after authorising, and what the nights scheduler calls directly.
  StatusOr<runs::Queued> Queue(const runs::Submission& submission);

 private:
  grpc::Status Authorize(grpc::ServerContext* ctx, Role need, Principal* who) const;
  grpc::Status Submit(const runs::Submission& submission, valvebench::v1::SubmitRunResponse* resp);
  grpc::Status FillRun(db::Store* store, const db::RunRecord& r, bool full, valvebench::v1::Run* out);
  grpc::Status LabBenches(valvebench::v1::ListBenchesResponse* resp);

  const ServiceSettings* settings_;
  const runs::Policy policy_;
  StorePool* pool_;
  runs::Registry* registry_;
  const std::vector<std::unique_ptr<runs::Worker>>* workers_;
};



}  // namespace vb::server
