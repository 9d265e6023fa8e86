// runs/spool.h: the host's local spool between the trace stream and the store (issue 39).
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <thread>

#include "db/sqlite_store.h"
#include "db/store.h"
#include "runs/admit.h"
#include "runs/execute.h"
#include "runs/spool.h"
#include "runs/worker.h"
#include "tests/runs/flaky_store.h"

namespace vb::runs {
namespace {

using testing::FlakyStore;

std::string Example(const std::string& rel) { return std::string(VB_SOURCE_DIR) + "/examples/" + rel; }

double NowUnixS() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

// A fresh directory under the test's temp dir.
std::string FreshDir(const std::string& name) {
  const std::string dir = ::testing::TempDir() + "/spool_test_" + std::to_string(::getpid()) + "_" + name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

// The POSIX env with a disk that fills up: appends fail with ENOSPC once `room` bytes were appended (after LevelDB's
// fault-injecting Env); or with EIO when io_error is set.
class FaultyEnv final : public SpoolEnv {
 public:
  std::atomic<std::int64_t> room{std::numeric_limits<std::int64_t>::max()};
  std::atomic<bool> io_error{false};

  Status CreateDir(const std::string& dir) override { return base_->CreateDir(dir); }
  StatusOr<std::vector<std::string>> ListDir(const std::string& dir) override { return base_->ListDir(dir); }
  StatusOr<std::unique_ptr<SpoolFile>> NewFile(const std::string& path) override {
    auto f = base_->NewFile(path);
    if (!f.ok()) return f.status();
    return std::unique_ptr<SpoolFile>(new File(this, std::move(*f), path));
  }
  Status ReadAt(const std::string& path, std::uint64_t offset, std::size_t n, std::string* out) override {
    return base_->ReadAt(path, offset, n, out);
  }
  Status Remove(const std::string& path) override { return base_->Remove(path); }
  Status SyncDir(const std::string& dir) override { return base_->SyncDir(dir); }
  void FreePrefix(const std::string& path, std::uint64_t length) override { base_->FreePrefix(path, length); }
  Status WriteSmallFile(const std::string& path, std::string_view contents) override {
    return base_->WriteSmallFile(path, contents);
  }
  StatusOr<std::string> ReadSmallFile(const std::string& path) override { return base_->ReadSmallFile(path); }

 private:
  class File final : public SpoolFile {
   public:
    File(FaultyEnv* env, std::unique_ptr<SpoolFile> f, std::string path)
        : env_(env), f_(std::move(f)), path_(std::move(path)) {}
    Status Append(std::string_view data) override {
      if (env_->io_error) return Status::ResourceExhausted("cannot write " + path_ + ": " + std::strerror(EIO));
      const std::int64_t left = env_->room.load();
      if (static_cast<std::int64_t>(data.size()) > left) {
        // A short write, as a full disk gives: the record is torn.
        if (left > 0) (void)f_->Append(data.substr(0, static_cast<std::size_t>(left)));
        env_->room = 0;
        return Status::ResourceExhausted("cannot write " + path_ + ": " + std::strerror(ENOSPC));
      }
      env_->room -= static_cast<std::int64_t>(data.size());
      return f_->Append(data);
    }
    Status Sync() override { return f_->Sync(); }

   private:
    FaultyEnv* env_;
    std::unique_ptr<SpoolFile> f_;
    std::string path_;
  };
  SpoolEnv* base_ = SpoolEnv::Default();
};

// A SQLite file store with one run of `spec` queued and claimed as host "h"; the spool's uploader gets its own
// connection to it, behind a FlakyStore the test controls (uploader()).
class SpoolRig {
 public:
  SpoolRig(const std::string& name, const experiment::ExperimentSpec& spec, bool paced) {
    dir_ = FreshDir(name);
    path_ = dir_ + "/runs.db";
    auto s = db::OpenSqliteStore(path_);
    EXPECT_TRUE(s.ok()) << s.status().ToString();
    store = std::move(*s);
    bench = LocalEmulatorSetup();
    bench.paced = paced;
    Policy local;
    local.benches = {bench};
    auto a = Admit({"me", "b", {spec}, {}, ""}, local);
    EXPECT_TRUE(a.ok()) << a.status().ToString();
    auto q = Enqueue(store.get(), std::move(*a), local);
    EXPECT_TRUE(q.ok());
    db::ClaimRequest claim = db::BenchClaim(bench.bench_class, bench.name);
    claim.host = "h";
    claim.lease_ttl_s = 30;
    auto c = store->ClaimNext(claim);
    EXPECT_TRUE(c.ok() && c->has_value());
    run = **c;
  }
  ~SpoolRig() { std::filesystem::remove_all(dir_); }

  std::unique_ptr<Spool> MakeSpool(SpoolEnv* env = nullptr, std::uint64_t max_bytes = std::uint64_t{1} << 30) {
    SpoolOptions o;
    o.dir = dir_ + "/spool";
    o.env = env;
    o.max_bytes = max_bytes;
    o.max_wait_s = 0.05;
    const std::string path = path_;
    auto spool = std::make_unique<Spool>(o, [this, path]() -> StatusOr<std::unique_ptr<db::Store>> {
      auto s = db::OpenSqliteStore(path);
      if (!s.ok()) return s.status();
      auto f = std::make_unique<FlakyStore>(std::move(*s));
      f->hang_ms = initial_hang_ms;
      f->down = initial_down;
      uploader_ = f.get();
      return std::unique_ptr<db::Store>(std::move(f));
    });
    EXPECT_TRUE(spool->Open().ok());
    return spool;
  }
  FlakyStore* uploader() { return uploader_; }

  std::int64_t StoredSamples(std::int64_t id) {
    std::int64_t stored = 0;
    EXPECT_TRUE(store->ForEachTraceChunk(id, [&](const db::TraceChunk&, std::int64_t total) {
      stored = total;
      return Status::Ok();
    }).ok());
    return stored;
  }
  int HistoryCount(std::int64_t id, db::RunStatus status) {
    auto h = store->History(id);
    EXPECT_TRUE(h.ok());
    return static_cast<int>(std::count_if(h->begin(), h->end(), [&](const db::StatusChange& c) { return c.status == status; }));
  }

  std::unique_ptr<db::Store> store;
  BenchSetup bench;
  db::RunRecord run;
  int initial_hang_ms = 0;
  bool initial_down = false;
  const std::string& dir() const { return dir_; }

 private:
  std::string dir_, path_;
  std::atomic<FlakyStore*> uploader_{nullptr};
};

// E1 paced for 2 s: 100 001 samples at 50 kHz, 7 chunks of 16384 (the stream holds 4 blocks).
experiment::ExperimentSpec PacedE1() {
  auto spec = experiment::LoadSpecFile(Example("standard/e1.json"));
  EXPECT_TRUE(spec.ok());
  spec->set_duration_s(2);
  return *spec;
}

experiment::ExperimentSpec E3() {
  auto spec = experiment::LoadSpecFile(Example("standard/e3.json"));
  EXPECT_TRUE(spec.ok());
  return *spec;
}

// The first limit: a database that does not answer held the trace stream's thread, and once its blocks
// were full the control loop waited. Without the spool the loop waits (the rig can tell); with it, never, and
// the whole trace lands once the store answers again.
TEST(Spool, TheLoopNeverWaitsForAStoreThatDoesNotAnswer) {
  {
    SpoolRig rig("direct", PacedE1(), true);
    FlakyStore slow(rig.store.get());
    slow.hang_ms = 700;  // each chunk write takes 0.7 s; the run produces one every 0.33 s
    ExecuteContext ctx;
    Outcome o = Execute(&slow, rig.run, rig.bench, ctx);
    ASSERT_EQ(o.status, db::RunStatus::kDone) << o.reason;
    EXPECT_GT(o.summary.record_waits, 0u) << "the rig's stalled store did not hold the loop up without the spool";
  }
  SpoolRig rig("spooled", PacedE1(), true);
  rig.initial_hang_ms = 700;
  auto spool = rig.MakeSpool();
  spool->Start();
  ExecuteContext ctx;
  ctx.spool = spool.get();
  ctx.retry.give_up_s = 60;
  Outcome o = Execute(rig.store.get(), rig.run, rig.bench, ctx);
  EXPECT_EQ(o.summary.record_waits, 0u);
  EXPECT_TRUE(o.recorded) << o.reason;
  EXPECT_EQ(o.status, db::RunStatus::kDone) << o.reason;
  EXPECT_EQ(o.summary.samples, 100'001u);
  EXPECT_EQ(rig.StoredSamples(rig.run.id), 100'001);
  EXPECT_EQ(rig.HistoryCount(rig.run.id, db::RunStatus::kDone), 1);
  EXPECT_FALSE(rig.store->GetMetrics(rig.run.id)->empty());
  EXPECT_TRUE(spool->Uploading().empty());
  EXPECT_EQ(spool->pending_bytes(), 0u);
  spool->Stop();
  // The journal is gone once its result landed.
  for (const auto& e : std::filesystem::directory_iterator(rig.dir() + "/spool"))
    EXPECT_EQ(e.path().extension(), "") << e.path();
}

// A result the store does not take in time stays in the spool (never dropped, never failed), the run stays
// running while the host uploads it (its lease is listed to be renewed), and it lands when the store is back.
TEST(Spool, AResultWaitingForTheStoreLandsWhenItIsBack) {
  SpoolRig rig("waiting", E3(), false);
  rig.initial_down = true;
  auto spool = rig.MakeSpool();
  Registry registry;  // what the API reads "result waiting for the store since ..." from
  spool->set_registry(&registry);
  spool->Start();
  ExecuteContext ctx;
  ctx.spool = spool.get();
  ctx.retry.give_up_s = 0.3;
  const double before = NowUnixS();
  Outcome o = Execute(rig.store.get(), rig.run, rig.bench, ctx);
  EXPECT_GE(registry.ResultWaitingSince(rig.run.id), before);
  EXPECT_LE(registry.ResultWaitingSince(rig.run.id), NowUnixS());
  EXPECT_TRUE(o.spooled);
  EXPECT_FALSE(o.recorded);
  EXPECT_FALSE(o.released);
  EXPECT_EQ(rig.store->GetRun(rig.run.id)->status, db::RunStatus::kRunning);
  const auto uploading = spool->Uploading();
  ASSERT_EQ(uploading.size(), 1u);
  EXPECT_EQ(uploading[0].run_id, rig.run.id);
  ASSERT_NE(rig.uploader(), nullptr);
  rig.uploader()->down = false;
  for (int k = 0; k < 500 && !spool->Uploading().empty(); ++k) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_TRUE(spool->Uploading().empty());
  auto r = rig.store->GetRun(rig.run.id);
  EXPECT_EQ(r->status, db::RunStatus::kDone) << r->reason;
  EXPECT_EQ(rig.StoredSamples(rig.run.id), 5001);
  EXPECT_EQ(rig.HistoryCount(rig.run.id, db::RunStatus::kDone), 1);
  EXPECT_EQ(registry.ResultWaitingSince(rig.run.id), 0.0);
  spool->Stop();  // before the registry it marks goes
}

// A disk that fills up mid-run stops the run: the loop ends at once (the bench to its safe state), the run fails
// with the disk's reason and marks the bench faulted; the chunks spooled before it are in the store, in order.
TEST(Spool, AFullDiskStopsTheRunSafelyWithTheReason) {
  SpoolRig rig("full", PacedE1(), true);
  FaultyEnv env;
  env.room = 3 * 1'600'000;  // three chunks of 16384 samples x 12 channels x 8 B and the begin record
  auto spool = rig.MakeSpool(&env);
  spool->Start();
  ExecuteContext ctx;
  ctx.spool = spool.get();
  ctx.retry.give_up_s = 30;
  Outcome o = Execute(rig.store.get(), rig.run, rig.bench, ctx);
  EXPECT_EQ(o.status, db::RunStatus::kFailed);
  EXPECT_TRUE(o.bench_fault);
  EXPECT_TRUE(o.recorded);
  EXPECT_NE(o.reason.find("No space left on device"), std::string::npos) << o.reason;
  EXPECT_NE(o.reason.find("spool"), std::string::npos) << o.reason;
  EXPECT_LT(o.summary.samples, 100'001u);
  auto r = rig.store->GetRun(rig.run.id);
  EXPECT_EQ(r->status, db::RunStatus::kFailed);
  EXPECT_NE(r->reason.find("No space left on device"), std::string::npos) << r->reason;
  const std::int64_t stored = rig.StoredSamples(rig.run.id);
  EXPECT_GT(stored, 0);
  EXPECT_EQ(stored % 16384, 0) << "a torn record reached the store";
  EXPECT_EQ(spool->pending_bytes(), 0u);
}

// The bound: with the store away, at most max_bytes wait in the spool; past it the run stops with the reason.
TEST(Spool, TheSpoolIsBoundedAndSaysSoWhenFull) {
  SpoolRig rig("bounded", PacedE1(), true);
  rig.initial_down = true;
  auto spool = rig.MakeSpool(nullptr, 4'000'000);
  spool->Start();
  ExecuteContext ctx;
  ctx.spool = spool.get();
  ctx.retry.give_up_s = 0.2;
  Outcome o = Execute(rig.store.get(), rig.run, rig.bench, ctx);
  EXPECT_EQ(o.status, db::RunStatus::kRunning);  // its result (failed) waits in the spool for the store
  EXPECT_TRUE(o.spooled);
  EXPECT_TRUE(o.bench_fault);
  EXPECT_LE(spool->pending_bytes(), 4'000'000u);
  rig.uploader()->down = false;
  for (int k = 0; k < 500 && !spool->Uploading().empty(); ++k) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  auto r = rig.store->GetRun(rig.run.id);
  EXPECT_EQ(r->status, db::RunStatus::kFailed);
  EXPECT_NE(r->reason.find("is full"), std::string::npos) << r->reason;
}

// An I/O error when the journal is created: the run fails before the bench is driven, as the host's fault.
TEST(Spool, ASpoolThatCannotBeWrittenFailsTheRunAsTheHostsFault) {
  SpoolRig rig("eio", E3(), false);
  FaultyEnv env;
  env.io_error = true;
  auto spool = rig.MakeSpool(&env);
  spool->Start();
  ExecuteContext ctx;
  ctx.spool = spool.get();
  Outcome o = Execute(rig.store.get(), rig.run, rig.bench, ctx);
  EXPECT_EQ(o.status, db::RunStatus::kFailed);
  EXPECT_TRUE(o.bench_fault);
  EXPECT_TRUE(o.recorded);
  EXPECT_NE(o.reason.find("Input/output error"), std::string::npos) << o.reason;
  EXPECT_EQ(o.summary.samples, 0u);
}

// A crash: what the journals hold is uploaded at the next start before anything else, once; a chunk the store
// already had (uploaded before the crash) is not written twice; an attempt without a result is dropped and its
// run interrupted with the time the process stopped, not the restart's.
TEST(Spool, AfterACrashTheLeftoversAreUploadedOnceAndTheStopIsDated) {
  SpoolRig rig("crash", E3(), false);
  // A second run, interrupted mid-run by the crash.
  Policy local;
  local.benches = {rig.bench};
  auto a = Admit({"me", "b2", {E3()}, {}, ""}, local);
  ASSERT_TRUE(a.ok());
  ASSERT_TRUE(Enqueue(rig.store.get(), std::move(*a), local).ok());
  db::ClaimRequest claim = db::BenchClaim(rig.bench.bench_class, rig.bench.name);
  claim.host = "h";
  claim.lease_ttl_s = 30;
  auto c2 = rig.store->ClaimNext(claim);
  ASSERT_TRUE(c2.ok() && c2->has_value());
  const db::RunRecord second = **c2;

  db::TraceChunk chunk;
  chunk.channels = {"t", "x"};
  chunk.samples = 3;
  chunk.sample_period_s = 0.001;
  const double crashed_at = NowUnixS();
  {
    auto spool = rig.MakeSpool();  // its uploader never starts: the process "crashes" with everything spooled
    auto j = spool->Begin(db::LeaseOf(rig.run));
    ASSERT_TRUE(j.ok());
    for (int k = 0; k < 3; ++k) {
      chunk.index = k;
      chunk.t0_s = 0.003 * k;
      chunk.data = {0.003 * k, 0.003 * k + 0.001, 0.003 * k + 0.002, 1.0 * k, 2.0 * k, 3.0 * k};
      ASSERT_TRUE((*j)->AppendChunk(chunk).ok());
      if (k == 0) {
        ASSERT_TRUE(rig.store->AppendTraceChunk(db::LeaseOf(rig.run), chunk).ok());  // uploaded before the crash
      }
    }
    // The result carries what executing the run measured, a paced loop's statistics included (written by the
    // same Finish when it is uploaded).
    db::ExecutionRecord executed;
    executed.wall_s = 0.5;
    executed.simulated_s = 0.009;
    executed.samples = executed.control_ticks = 9;
    executed.loop.emplace();
    executed.loop->ticks = 9;
    executed.loop->overruns = 2;
    executed.loop->jitter_p50_s = 1e-5;
    executed.loop->jitter_p99_s = 4e-5;
    executed.loop->jitter_max_s = 6e-5;
    executed.build = "valvebench 0.1.0 sha256:0123456789abcdef0123456789abcdef";
    ASSERT_TRUE((*j)->AppendResult({db::RunStatus::kDone, "", {{"rise_time_s", 0.01}}, -1.0, executed}).ok());
    auto j2 = spool->Begin(db::LeaseOf(second));
    ASSERT_TRUE(j2.ok());
    chunk.index = 0;
    ASSERT_TRUE((*j2)->AppendChunk(chunk).ok());
  }
  // Garbage after the first journal's result (a record torn by the crash) is ignored.
  for (const auto& e : std::filesystem::directory_iterator(rig.dir() + "/spool")) {
    if (e.path().filename().string().find("run-" + std::to_string(rig.run.id) + "-f") != std::string::npos)
      std::ofstream(e.path(), std::ios::app) << "torn";
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(400));
  const double restarted_at = NowUnixS();

  auto spool = rig.MakeSpool();
  RetryPolicy retry;
  retry.give_up_s = 5;
  auto left = spool->DrainLeftovers(rig.store.get(), retry, nullptr);
  ASSERT_TRUE(left.ok()) << left.status().ToString();
  EXPECT_EQ(left->results_landed, 1);
  EXPECT_EQ(left->dropped, 1);
  EXPECT_EQ(left->stale, 0);
  EXPECT_GE(left->stopped_unix_s, crashed_at - 0.5);
  EXPECT_LT(left->stopped_unix_s, restarted_at - 0.3);
  auto r = rig.store->GetRun(rig.run.id);
  EXPECT_EQ(r->status, db::RunStatus::kDone) << r->reason;
  EXPECT_EQ(rig.StoredSamples(rig.run.id), 9);
  EXPECT_EQ(rig.HistoryCount(rig.run.id, db::RunStatus::kDone), 1);
  ASSERT_EQ(rig.store->GetMetrics(rig.run.id)->size(), 1u);
  ASSERT_TRUE(r->execution.has_value()) << "the journal's execution record was uploaded with the result";
  EXPECT_EQ(r->execution->samples, 9);
  EXPECT_EQ(r->execution->wall_s, 0.5);
  ASSERT_TRUE(r->execution->loop.has_value());
  EXPECT_EQ(r->execution->loop->overruns, 2);
  EXPECT_EQ(r->execution->loop->jitter_p99_s, 4e-5);
  EXPECT_EQ(r->execution->build, "valvebench 0.1.0 sha256:0123456789abcdef0123456789abcdef");

  ASSERT_EQ(*rig.store->RecoverAfterCrashAt("h", left->stopped_unix_s), 1);
  auto h = rig.store->History(second.id);
  ASSERT_TRUE(h.ok());
  bool seen = false;
  for (const auto& change : *h)
    if (change.status == db::RunStatus::kInterrupted) {
      seen = true;
      EXPECT_NEAR(change.at_unix_s, left->stopped_unix_s, 1e-3);
      EXPECT_LT(change.at_unix_s, restarted_at - 0.3);
    }
  EXPECT_TRUE(seen);
  EXPECT_EQ(rig.store->GetRun(second.id)->status, db::RunStatus::kQueued);
  // Nothing left to drain a second time.
  auto again = spool->DrainLeftovers(rig.store.get(), retry, nullptr);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->results_landed + again->dropped, 0);
}

// A corrupt chunk record (the disk changed it) is not uploaded: the run fails with the reason, never silently.
TEST(Spool, ACorruptRecordFailsTheRunWithTheReason) {
  SpoolRig rig("corrupt", E3(), false);
  rig.initial_down = true;
  auto spool = rig.MakeSpool();
  auto j = spool->Begin(db::LeaseOf(rig.run));
  ASSERT_TRUE(j.ok());
  db::TraceChunk chunk;
  chunk.channels = {"t"};
  chunk.samples = 2;
  chunk.data = {0.0, 0.5};
  ASSERT_TRUE((*j)->AppendChunk(chunk).ok());
  // Flip one byte inside the chunk's data.
  std::string path;
  for (const auto& e : std::filesystem::directory_iterator(rig.dir() + "/spool"))
    if (e.path().extension() == ".journal") path = e.path();
  ASSERT_FALSE(path.empty());
  {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(std::filesystem::file_size(path) - 3));
    f.put('\x55');
  }
  ASSERT_TRUE((*j)->AppendResult({db::RunStatus::kDone, "", {}, -1.0, std::nullopt}).ok());
  rig.initial_down = false;
  spool->Start();
  EXPECT_EQ((*j)->WaitForResult(10, nullptr), Journal::State::kLanded);
  auto r = rig.store->GetRun(rig.run.id);
  EXPECT_EQ(r->status, db::RunStatus::kFailed);
  EXPECT_NE(r->reason.find("checksum mismatch"), std::string::npos) << r->reason;
  EXPECT_EQ(rig.StoredSamples(rig.run.id), 0);
}

TEST(SpoolFormat, Crc32IsZlibs) {
  EXPECT_EQ(spool_format::Crc32("123456789"), 0xCBF43926u);  // the CRC-32 check value
}

}  // namespace
}  // namespace vb::runs
