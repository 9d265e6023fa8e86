// A db::Store that fails on purpose (after LevelDB's fault-injecting Env): it forwards every call to a real
// store, and the writes of a run's path (trace chunks, progress, the result) can be made to fail as a lost
// connection does: Unavailable before the write ("down"), or Unavailable after the write committed (its answer
// lost). For the tests of a run that survives its store (issue 30).
#pragma once

#include <atomic>
#include <chrono>
#include <memory>
#include <thread>
#include <string>

#include "db/store.h"

namespace vb::runs::testing {

class FlakyStore final : public db::Store {
 public:
  explicit FlakyStore(db::Store* inner) : inner_(inner) {}
  // Owning its connection (a spool's uploader opens its own: runs/spool.h).
  explicit FlakyStore(std::unique_ptr<db::Store> owned) : owned_(std::move(owned)), inner_(owned_.get()) {}

  // While > 0, AppendTraceChunk and Finish take this long before they answer, as a database that does not answer
  // until its deadline (a SIGSTOPped PostgreSQL) holds the caller.
  std::atomic<int> hang_ms{0};

  // While down, every write of a run's path (and ClaimNext) fails before reaching the store.
  std::atomic<bool> down{false};
  // The next N Finish calls commit and then report Unavailable, as a connection dropped after COMMIT would.
  std::atomic<int> lose_finish_answers{0};
  // The next N AppendTraceChunk calls commit and then report Unavailable.
  std::atomic<int> lose_chunk_answers{0};
  // The next N Finish calls fail before reaching the store.
  std::atomic<int> fail_finishes{0};
  std::atomic<int> failed_writes{0};
  std::atomic<int> finish_calls{0};

  int schema_version() const override { return inner_->schema_version(); }
  StatusOr<std::int64_t> SubmitBatch(const std::string& submitter, const std::string& name,
                                     const std::string& batch_spec_json, std::vector<db::RunRecord> runs,
                                     std::vector<std::int64_t>* run_ids) override {
    return inner_->SubmitBatch(submitter, name, batch_spec_json, std::move(runs), run_ids);
  }
  StatusOr<std::optional<db::RunRecord>> ClaimNext(const db::ClaimRequest& request) override {
    if (down) return Down();
    return inner_->ClaimNext(request);
  }
  Status SetProgress(const db::Lease& lease, double progress) override {
    if (down) return Down();
    return inner_->SetProgress(lease, progress);
  }
  using db::Store::Finish;
  Status Finish(const db::Lease& lease, db::RunStatus final_status, const std::string& reason,
                const std::vector<db::Metric>& metrics,
                const std::optional<db::ExecutionRecord>& execution) override {
    ++finish_calls;
    Hang();
    if (down) return Down();
    if (fail_finishes.load() > 0) {
      --fail_finishes;
      return Down();
    }
    Status st = inner_->Finish(lease, final_status, reason, metrics, execution);
    if (st.ok() && lose_finish_answers.load() > 0) {
      --lose_finish_answers;
      return Down();
    }
    return st;
  }
  StatusOr<db::RunStatus> RequestCancel(std::int64_t run_id, const std::string& reason) override {
    return inner_->RequestCancel(run_id, reason);
  }
  StatusOr<bool> CancelRequested(std::int64_t run_id) override {
    if (down) return Down();
    return inner_->CancelRequested(run_id);
  }
  StatusOr<int> RecoverAfterCrash(const std::string& host) override { return inner_->RecoverAfterCrash(host); }
  StatusOr<int> RecoverAfterCrashAt(const std::string& host, double stopped_unix_s) override {
    return inner_->RecoverAfterCrashAt(host, stopped_unix_s);
  }
  Status Heartbeat(const db::HostRecord& host, double lease_ttl_s, const std::vector<db::Lease>& executing) override {
    if (down) return Down();
    return inner_->Heartbeat(host, lease_ttl_s, executing);
  }
  StatusOr<std::vector<db::HostRecord>> ListHosts() override { return inner_->ListHosts(); }
  StatusOr<std::vector<std::int64_t>> RequeueLapsed() override { return inner_->RequeueLapsed(); }
  StatusOr<std::vector<db::StaleWrite>> StaleWrites(std::int32_t limit, std::int64_t* total) override {
    return inner_->StaleWrites(limit, total);
  }
  StatusOr<bool> ClaimNight(const std::string& night, const std::string& host) override {
    return inner_->ClaimNight(night, host);
  }
  StatusOr<db::RunRecord> GetRun(std::int64_t run_id) override {
    if (down) return Down();
    return inner_->GetRun(run_id);
  }
  StatusOr<std::vector<db::RunRecord>> ListRuns(const db::RunFilter& filter) override { return inner_->ListRuns(filter); }
  StatusOr<std::int64_t> CountRuns(const db::RunFilter& filter) override { return inner_->CountRuns(filter); }
  StatusOr<std::vector<db::StatusChange>> History(std::int64_t run_id) override { return inner_->History(run_id); }
  StatusOr<std::vector<db::Metric>> GetMetrics(std::int64_t run_id) override { return inner_->GetMetrics(run_id); }
  StatusOr<std::int64_t> CountQueued(const std::string& submitter) override { return inner_->CountQueued(submitter); }
  StatusOr<std::int64_t> StoredTraceBytes(const std::string& submitter) override {
    return inner_->StoredTraceBytes(submitter);
  }
  Status AppendTraceChunk(const db::Lease& lease, const db::TraceChunk& chunk) override {
    Hang();
    if (down) return Down();
    Status st = inner_->AppendTraceChunk(lease, chunk);
    if (st.ok() && lose_chunk_answers.load() > 0) {
      --lose_chunk_answers;
      return Down();
    }
    return st;
  }
  StatusOr<std::vector<db::TraceChunk>> ReadTrace(std::int64_t run_id) override { return inner_->ReadTrace(run_id); }
  Status ForEachTraceChunk(std::int64_t run_id,
                           const std::function<Status(const db::TraceChunk&, std::int64_t)>& fn) override {
    return inner_->ForEachTraceChunk(run_id, fn);
  }
  StatusOr<std::int32_t> SaveBaseline(const std::string& name, const std::string& source, const std::string& note,
                                      const std::vector<db::BaselineEntry>& entries) override {
    return inner_->SaveBaseline(name, source, note, entries);
  }
  StatusOr<db::BaselineRecord> GetBaseline(const std::string& name, std::int32_t version) override {
    return inner_->GetBaseline(name, version);
  }
  StatusOr<std::vector<db::BaselineRecord>> ListBaselines() override { return inner_->ListBaselines(); }
  StatusOr<std::int64_t> SaveRegression(const db::RegressionRecord& record) override {
    return inner_->SaveRegression(record);
  }
  StatusOr<db::RegressionRecord> GetRegression(std::int64_t id) override { return inner_->GetRegression(id); }
  StatusOr<std::vector<db::RegressionRecord>> ListRegressions(bool nights_only, std::int32_t limit) override {
    return inner_->ListRegressions(nights_only, limit);
  }
  StatusOr<db::PruneResult> Prune(const db::PruneRequest& request) override { return inner_->Prune(request); }

 private:
  void Hang() {
    if (const int ms = hang_ms.load(); ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(ms));
  }
  Status Down() {
    ++failed_writes;
    return Status::Unavailable("store unavailable: injected (tests/runs/flaky_store.h)");
  }
  std::unique_ptr<db::Store> owned_;
  db::Store* inner_;
};

}  // namespace vb::runs::testing
