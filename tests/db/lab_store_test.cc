// The lab's store methods (docs/lab.md): claims carry a fencing token, a host and a lease; writes with a stale
// fence are refused and recorded; lapsed leases are re-queued; aging lifts old runs; one night per lab; hosts and
// their heartbeats. Written against std::unique_ptr<db::Store> through a factory, so the same tests run on any
// engine: LabStoreEngines below lists them (SQLite here; another engine adds its factory).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "db/open_store.h"
#include "db/sqlite_store.h"
#include "db/store.h"
#include "db/text.h"
#include "tests/db/store_engines.h"

namespace vb::db {
namespace {

using namespace std::chrono_literals;

double NowS() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

// An engine: opens connection k (0, 1, ...) to one shared, initially empty database named by the test.
struct Engine {
  std::string name;
  std::function<std::unique_ptr<Store>(const std::string& db_name)> open;
  std::function<void(const std::string& db_name)> drop;
};

std::string SqlitePath(const std::string& db_name) {
  return Cat(::testing::TempDir(), "vb_lab_store_test_", db_name, "_", getpid(), ".db");
}
void DropSqlite(const std::string& db_name) {
  for (const char* suffix : {"", "-wal", "-shm"}) std::remove((SqlitePath(db_name) + suffix).c_str());
}

// PostgreSQL (tests/db/store_engines.h): a fresh database per test, its location kept for further connections.
std::map<std::string, std::string>& PgLocations() {
  static std::map<std::string, std::string> locations;
  return locations;
}
std::string& PgSkipReason() {
  static std::string reason;
  return reason;
}

std::vector<Engine> LabStoreEngines() {
  return {{"sqlite",
           [](const std::string& db_name) {
             auto s = OpenSqliteStore(SqlitePath(db_name));
             EXPECT_TRUE(s.ok()) << s.status().ToString();
             return s.ok() ? std::move(s).value() : nullptr;
           },
           DropSqlite},
          {"postgresql",
           [](const std::string& db_name) -> std::unique_ptr<Store> {
             auto it = PgLocations().find(db_name);
             if (it == PgLocations().end()) {
               std::string location;
               auto s = testing::OpenFreshStore("postgresql", &location);
               if (!s.ok()) {
                 PgSkipReason() = s.status().message();
                 return nullptr;
               }
               PgLocations()[db_name] = location;
               return std::move(s).value();
             }
             auto s = OpenStore(it->second);
             EXPECT_TRUE(s.ok()) << s.status().ToString();
             return s.ok() ? std::move(s).value() : nullptr;
           },
           [](const std::string& db_name) { PgLocations().erase(db_name); }}};
}

class LabStoreTest : public ::testing::TestWithParam<Engine> {
 protected:
  void SetUp() override {
    db_name_ = ::testing::UnitTest::GetInstance()->current_test_info()->name();
    for (char& c : db_name_)
      if (c == '/') c = '_';
    GetParam().drop(db_name_);
    store_ = Open();
    if (store_ == nullptr && GetParam().name == "postgresql" && !PgSkipReason().empty())
      GTEST_SKIP() << "PostgreSQL cannot start here: " << PgSkipReason();
    ASSERT_NE(store_, nullptr);
  }
  void TearDown() override {
    store_.reset();
    GetParam().drop(db_name_);
  }
  // Another connection to the same database (another host, in the tests).
  std::unique_ptr<Store> Open() { return GetParam().open(db_name_); }

  std::vector<std::int64_t> SubmitRuns(int n, std::int32_t priority = 0) {
    std::vector<RunRecord> runs;
    for (int k = 0; k < n; ++k) {
      RunRecord r;
      r.key = NamedRun(Cat("run", k));
      r.controller = "pi_current";
      r.bench_kind = "emulated";
      r.spec_json = "{}";
      r.priority = priority;
      runs.push_back(std::move(r));
    }
    std::vector<std::int64_t> ids;
    auto b = store_->SubmitBatch("alice", "batch", "{}", std::move(runs), &ids);
    EXPECT_TRUE(b.ok()) << b.status().ToString();
    return ids;
  }

  static ClaimRequest Claim(const std::string& host, const std::string& bench, double ttl_s = 0.0,
                            double aging_s = 0.0) {
    ClaimRequest r = BenchClaim("emulated", bench);
    r.host = host;
    r.lease_ttl_s = ttl_s;
    r.aging_s = aging_s;
    return r;
  }

  RunRecord ClaimOrDie(Store* store, const ClaimRequest& request) {
    auto c = store->ClaimNext(request);
    EXPECT_TRUE(c.ok()) << c.status().ToString();
    if (!c.ok() || !c->has_value()) {
      ADD_FAILURE() << "nothing claimed";
      return {};
    }
    return **c;
  }

  static TraceChunk Chunk(int index) {
    TraceChunk c;
    c.index = index;
    c.sample_period_s = 1e-3;
    c.t0_s = index * 4e-3;
    c.samples = 4;
    c.channels = {"i_A"};
    c.data = {1, 2, 3, 4};
    return c;
  }

  int Count(const std::vector<StatusChange>& history, RunStatus s) {
    int n = 0;
    for (const auto& h : history) n += h.status == s;
    return n;
  }

  std::string db_name_;
  std::unique_ptr<Store> store_;
};

TEST_P(LabStoreTest, EveryClaimIsANewAttemptWithItsFenceHostAndLease) {
  const auto ids = SubmitRuns(2);
  const double before = NowS();
  RunRecord a = ClaimOrDie(store_.get(), Claim("host-a", "bench-1", 10.0));
  EXPECT_EQ(a.id, ids[0]);
  EXPECT_EQ(a.fence, 1);
  EXPECT_EQ(a.host, "host-a");
  EXPECT_GE(a.lease_expires_unix_s, before + 10.0);
  EXPECT_LE(a.lease_expires_unix_s, NowS() + 10.0);
  // Without a TTL (one machine): no lease, and the record read back says so.
  RunRecord b = ClaimOrDie(store_.get(), Claim("", "bench-2"));
  EXPECT_EQ(b.fence, 1);
  EXPECT_EQ(b.host, "");
  EXPECT_EQ(b.lease_expires_unix_s, 0.0);
  auto again = store_->GetRun(a.id);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->fence, 1);
  EXPECT_EQ(again->host, "host-a");
  auto hist = store_->History(a.id);
  ASSERT_TRUE(hist.ok());
  EXPECT_NE(hist->back().reason.find("on host host-a"), std::string::npos) << hist->back().reason;
}

TEST_P(LabStoreTest, BadClaimRequestsNameTheField) {
  SubmitRuns(1);
  auto c = store_->ClaimNext(Claim("h", "b", -1.0));
  EXPECT_EQ(c.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(c.status().message().find("lease_ttl_s"), std::string::npos) << c.status().message();
  c = store_->ClaimNext(Claim("h", "b", 1.0, std::nan("")));
  EXPECT_EQ(c.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(c.status().message().find("aging_s"), std::string::npos) << c.status().message();
  EXPECT_EQ(store_->Heartbeat(HostRecord{}, 1.0, {}).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->Heartbeat(HostRecord{"h", "", "[]", 0, 0}, -1.0, {}).code(), StatusCode::kInvalidArgument);
}

// The scenario the fence exists for: host A stops (SIGSTOP), its lease lapses, the run is re-queued and host B
// takes it; A comes back and tries to write. Every one of A's writes is refused and recorded; B's result stands.
TEST_P(LabStoreTest, AWriteWithAStaleFenceIsRefusedRecordedAndChangesNothing) {
  const auto ids = SubmitRuns(1);
  auto host_b = Open();
  RunRecord a = ClaimOrDie(store_.get(), Claim("host-a", "bench-a", 0.2));
  ASSERT_TRUE(store_->AppendTraceChunk(LeaseOf(a), Chunk(0)).ok());
  std::this_thread::sleep_for(350ms);  // no heartbeat from A
  auto lapsed = host_b->RequeueLapsed();
  ASSERT_TRUE(lapsed.ok()) << lapsed.status().ToString();
  ASSERT_EQ(*lapsed, std::vector<std::int64_t>{ids[0]});
  RunRecord b = ClaimOrDie(host_b.get(), Claim("host-b", "bench-b", 10.0));
  EXPECT_EQ(b.id, ids[0]);
  EXPECT_EQ(b.fence, 2);
  ASSERT_TRUE(host_b->AppendTraceChunk(LeaseOf(b), Chunk(0)).ok());

  // A, late: progress, its next trace chunk and its result.
  Status p = store_->SetProgress(LeaseOf(a), 0.9);
  EXPECT_EQ(p.code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(p.message().rfind("stale write", 0), 0u) << p.message();
  EXPECT_NE(p.message().find("host host-b"), std::string::npos) << p.message();
  Status t = store_->AppendTraceChunk(LeaseOf(a), Chunk(1));
  EXPECT_EQ(t.code(), StatusCode::kFailedPrecondition);
  Status f = store_->Finish(LeaseOf(a), RunStatus::kDone, "", {{"rmse_A", 99.0}});
  EXPECT_EQ(f.code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(f.message().rfind("stale write", 0), 0u) << f.message();

  // Nothing of A's landed: B's chunk 0 is the only chunk, the run is still B's, no metrics.
  auto run = store_->GetRun(ids[0]);
  ASSERT_TRUE(run.ok());
  EXPECT_EQ(run->status, RunStatus::kRunning);
  EXPECT_EQ(run->host, "host-b");
  EXPECT_EQ(run->progress, 0.0);
  auto trace = store_->ReadTrace(ids[0]);
  ASSERT_TRUE(trace.ok());
  EXPECT_EQ(trace->size(), 1u);
  EXPECT_TRUE(store_->GetMetrics(ids[0])->empty());

  // B finishes; the result is B's, once.
  ASSERT_TRUE(host_b->Finish(LeaseOf(b), RunStatus::kDone, "", {{"rmse_A", 0.01}}).ok());
  auto metrics = store_->GetMetrics(ids[0]);
  ASSERT_TRUE(metrics.ok());
  ASSERT_EQ(metrics->size(), 1u);
  EXPECT_EQ((*metrics)[0].value, 0.01);
  auto hist = store_->History(ids[0]);
  ASSERT_TRUE(hist.ok());
  EXPECT_EQ(Count(*hist, RunStatus::kDone), 1);
  EXPECT_EQ(Count(*hist, RunStatus::kInterrupted), 1);

  // The refusals, in order, with the fences and who held the run.
  std::int64_t total = 0;
  auto stale = host_b->StaleWrites(100, &total);
  ASSERT_TRUE(stale.ok()) << stale.status().ToString();
  EXPECT_EQ(total, 3);
  ASSERT_EQ(stale->size(), 3u);
  EXPECT_EQ((*stale)[0].what, "progress");
  EXPECT_EQ((*stale)[1].what, "trace chunk 1");
  EXPECT_EQ((*stale)[2].what, "finish done");
  for (const auto& w : *stale) {
    EXPECT_EQ(w.run_id, ids[0]);
    EXPECT_EQ(w.fence, 1);
    EXPECT_EQ(w.current_fence, 2);
    EXPECT_EQ(w.host, "host-b");
    EXPECT_GT(w.at_unix_s, 0.0);
  }
  // A second finish by B itself (its run has ended) is refused too: a result is written once.
  EXPECT_EQ(host_b->Finish(LeaseOf(b), RunStatus::kFailed, "again", {}).code(), StatusCode::kFailedPrecondition);
  ASSERT_TRUE(host_b->StaleWrites(1, &total).ok());
  EXPECT_EQ(total, 4);
  EXPECT_EQ(store_->StaleWrites(0, &total).status().code(), StatusCode::kInvalidArgument);
}

TEST_P(LabStoreTest, AWriteForAReQueuedRunIsStaleEvenBeforeAnotherHostTakesIt) {
  const auto ids = SubmitRuns(1);
  RunRecord a = ClaimOrDie(store_.get(), Claim("host-a", "bench-a", 0.1));
  std::this_thread::sleep_for(250ms);
  ASSERT_EQ(store_->RequeueLapsed()->size(), 1u);
  Status f = store_->Finish(LeaseOf(a), RunStatus::kDone, "", {});
  EXPECT_EQ(f.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(f.message().find("is queued, not running"), std::string::npos) << f.message();
  EXPECT_EQ(store_->GetRun(ids[0])->status, RunStatus::kQueued);
  std::int64_t total = 0;
  auto stale = store_->StaleWrites(10, &total);
  ASSERT_TRUE(stale.ok());
  ASSERT_EQ(total, 1);
  EXPECT_EQ((*stale)[0].host, "");  // nobody holds it
}

TEST_P(LabStoreTest, HeartbeatsKeepLeasesAndALapsedLeaseIsReQueuedWithItsIdPriorityAndAge) {
  std::vector<RunRecord> runs(1);
  runs[0].key = NamedRun("urgent");
  runs[0].bench_kind = "emulated";
  runs[0].spec_json = "{}";
  runs[0].priority = 7;
  std::vector<std::int64_t> ids;
  ASSERT_TRUE(store_->SubmitBatch("alice", "b", "{}", runs, &ids).ok());
  const double submitted = store_->GetRun(ids[0])->submitted_unix_s;
  RunRecord a = ClaimOrDie(store_.get(), Claim("host-a", "bench-a", 0.3));
  // Heartbeats every 0.1 s for 0.6 s (twice the TTL): the lease holds.
  for (int k = 0; k < 6; ++k) {
    ASSERT_TRUE(store_->Heartbeat(HostRecord{"host-a", "a:1", "[]", 0, 0}, 0.3, {LeaseOf(a)}).ok());
    std::this_thread::sleep_for(100ms);
    auto lapsed = store_->RequeueLapsed();
    ASSERT_TRUE(lapsed.ok());
    EXPECT_TRUE(lapsed->empty()) << "lapsed at heartbeat " << k;
  }
  EXPECT_GT(store_->GetRun(ids[0])->lease_expires_unix_s, a.lease_expires_unix_s);
  // Another host's heartbeat does not renew A's lease.
  auto other = Open();
  std::this_thread::sleep_for(450ms);
  ASSERT_TRUE(other->Heartbeat(HostRecord{"host-b", "b:1", "[]", 0, 0}, 0.3, {LeaseOf(a)}).ok());
  auto lapsed = other->RequeueLapsed();
  ASSERT_TRUE(lapsed.ok());
  ASSERT_EQ(*lapsed, std::vector<std::int64_t>{ids[0]});
  auto run = store_->GetRun(ids[0]);
  ASSERT_TRUE(run.ok());
  EXPECT_EQ(run->status, RunStatus::kQueued);
  EXPECT_EQ(run->priority, 7);
  EXPECT_EQ(run->submitted_unix_s, submitted);
  EXPECT_EQ(run->host, "");
  EXPECT_EQ(run->lease_expires_unix_s, 0.0);
  EXPECT_EQ(run->fence, 1);  // the next claim takes 2
  auto hist = store_->History(ids[0]);
  ASSERT_TRUE(hist.ok());
  ASSERT_GE(hist->size(), 2u);
  EXPECT_EQ((*hist)[hist->size() - 2].status, RunStatus::kInterrupted);
  EXPECT_NE((*hist)[hist->size() - 2].reason.find("lease lapsed: host host-a"), std::string::npos);
  EXPECT_TRUE(other->RequeueLapsed()->empty());  // once
  EXPECT_EQ(ClaimOrDie(other.get(), Claim("host-b", "bench-b", 10.0)).fence, 2);
}

// Issue 30: a heartbeat renews only the leases the host says it is executing. A run of the host that is not
// among them (its experiment ended and its result could not be written yet) lapses and is re-queued, so it is
// never left running with nobody executing it; nor does a lease with an old fence renew a re-claimed run.
TEST_P(LabStoreTest, AHeartbeatRenewsOnlyTheLeasesOfRunsItIsExecuting) {
  SubmitRuns(2);
  RunRecord executing = ClaimOrDie(store_.get(), Claim("host-a", "bench-a", 0.3));
  RunRecord ended = ClaimOrDie(store_.get(), Claim("host-a", "bench-b", 0.3));
  for (int k = 0; k < 6; ++k) {
    ASSERT_TRUE(store_->Heartbeat(HostRecord{"host-a", "a:1", "[]", 0, 0}, 0.3, {LeaseOf(executing)}).ok());
    std::this_thread::sleep_for(100ms);
  }
  auto lapsed = store_->RequeueLapsed();
  ASSERT_TRUE(lapsed.ok()) << lapsed.status().ToString();
  EXPECT_EQ(*lapsed, std::vector<std::int64_t>{ended.id});
  EXPECT_EQ(store_->GetRun(executing.id)->status, RunStatus::kRunning);
  EXPECT_EQ(store_->GetRun(ended.id)->status, RunStatus::kQueued);
  // The re-queued run claimed again (fence 2): a heartbeat naming its old attempt does not renew the new one.
  RunRecord again = ClaimOrDie(store_.get(), Claim("host-a", "bench-b", 0.3));
  ASSERT_EQ(again.id, ended.id);
  ASSERT_EQ(again.fence, 2);
  for (int k = 0; k < 6; ++k) {
    ASSERT_TRUE(
        store_->Heartbeat(HostRecord{"host-a", "a:1", "[]", 0, 0}, 0.3, {LeaseOf(executing), LeaseOf(ended)}).ok());
    std::this_thread::sleep_for(100ms);
  }
  lapsed = store_->RequeueLapsed();
  ASSERT_TRUE(lapsed.ok());
  EXPECT_EQ(*lapsed, std::vector<std::int64_t>{ended.id});
}

// Issue 30: a Finish retried after its answer was lost (the connection dropped after COMMIT) finds the run in
// exactly the state it writes: Ok, written once, not a stale write. A different final state is still refused.
TEST_P(LabStoreTest, ARetriedFinishWhoseFirstTryCommittedIsNotAStaleWrite) {
  SubmitRuns(1);
  RunRecord a = ClaimOrDie(store_.get(), Claim("host-a", "bench-a", 10.0));
  ASSERT_TRUE(store_->Finish(LeaseOf(a), RunStatus::kDone, "ok", {{"rmse_A", 0.5}}).ok());
  EXPECT_TRUE(store_->Finish(LeaseOf(a), RunStatus::kDone, "ok", {{"rmse_A", 0.5}}).ok());
  EXPECT_EQ(store_->GetMetrics(a.id)->size(), 1u);
  EXPECT_EQ(store_->Finish(LeaseOf(a), RunStatus::kFailed, "late", {}).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->Finish(LeaseOf(a), RunStatus::kDone, "other reason", {}).code(),
            StatusCode::kFailedPrecondition);
  auto hist = store_->History(a.id);
  ASSERT_TRUE(hist.ok());
  EXPECT_EQ(std::count_if(hist->begin(), hist->end(), [](const StatusChange& c) { return c.status == RunStatus::kDone; }),
            1);
  std::int64_t total = 0;
  ASSERT_TRUE(store_->StaleWrites(10, &total).ok());
  EXPECT_EQ(total, 2);  // the two different ones
}

TEST_P(LabStoreTest, RunsWithoutALeaseNeverLapse) {
  SubmitRuns(1);
  ClaimOrDie(store_.get(), Claim("", "bench-1"));
  std::this_thread::sleep_for(50ms);
  auto lapsed = store_->RequeueLapsed();
  ASSERT_TRUE(lapsed.ok());
  EXPECT_TRUE(lapsed->empty());
}

TEST_P(LabStoreTest, AgingLetsAnOldLowPriorityRunPassNewerHigherOnes) {
  const auto old_ids = SubmitRuns(1, 0);
  std::this_thread::sleep_for(700ms);
  const auto new_ids = SubmitRuns(1, 2);
  // With aging_s = 0.2 the old run has waited >= 3 steps: 0 + 3 > 2 + 0.
  RunRecord first = ClaimOrDie(store_.get(), Claim("h", "b1", 0.0, 0.2));
  EXPECT_EQ(first.id, old_ids[0]);
  RunRecord second = ClaimOrDie(store_.get(), Claim("h", "b2", 0.0, 0.2));
  EXPECT_EQ(second.id, new_ids[0]);

  // The same queue shape claimed without aging (another host): priority first.
  auto peek = Open();
  const auto old2 = SubmitRuns(1, 0);
  std::this_thread::sleep_for(700ms);
  const auto new2 = SubmitRuns(1, 2);
  EXPECT_EQ(ClaimOrDie(peek.get(), Claim("h", "b3")).id, new2[0]);
  EXPECT_EQ(ClaimOrDie(peek.get(), Claim("h", "b4")).id, old2[0]);
}

TEST_P(LabStoreTest, RecoverAfterCrashTouchesOnlyTheRestartedHostsRuns) {
  const auto ids = SubmitRuns(3);
  auto b = Open();
  RunRecord ra = ClaimOrDie(store_.get(), Claim("host-a", "bench-a", 10.0));
  RunRecord rb = ClaimOrDie(b.get(), Claim("host-b", "bench-b", 10.0));
  auto n = store_->RecoverAfterCrash("host-a");
  ASSERT_TRUE(n.ok()) << n.status().ToString();
  EXPECT_EQ(*n, 1);
  EXPECT_EQ(store_->GetRun(ra.id)->status, RunStatus::kQueued);
  EXPECT_EQ(store_->GetRun(rb.id)->status, RunStatus::kRunning);
  EXPECT_TRUE(b->Finish(LeaseOf(rb), RunStatus::kDone, "", {}).ok());
  // "" (one machine): every running run.
  RunRecord again = ClaimOrDie(b.get(), Claim("host-b", "bench-b", 10.0));
  EXPECT_EQ(*store_->RecoverAfterCrash(""), 1);
  EXPECT_EQ(store_->GetRun(again.id)->status, RunStatus::kQueued);
}

// Issue 39: the interrupted entry carries the time the host stopped (its spool's last sign of life), on both
// engines; the re-queue is dated now; a stop time in the store's future is taken as now.
TEST_P(LabStoreTest, RecoverAfterCrashAtDatesTheInterruptionWithTheStop) {
  (void)SubmitRuns(2);
  RunRecord r = ClaimOrDie(store_.get(), Claim("host-a", "bench-a", 10.0));
  const double stopped = NowS() - 100.0;
  auto n = store_->RecoverAfterCrashAt("host-a", stopped);
  ASSERT_TRUE(n.ok()) << n.status().ToString();
  EXPECT_EQ(*n, 1);
  auto h = store_->History(r.id);
  ASSERT_TRUE(h.ok());
  ASSERT_GE(h->size(), 2u);
  EXPECT_EQ((*h)[h->size() - 2].status, RunStatus::kInterrupted);
  EXPECT_NEAR((*h)[h->size() - 2].at_unix_s, stopped, 1e-3);
  EXPECT_EQ(h->back().status, RunStatus::kQueued);
  EXPECT_GT(h->back().at_unix_s, stopped + 90.0);
  RunRecord again = ClaimOrDie(store_.get(), Claim("host-a", "bench-a", 10.0));
  ASSERT_TRUE(store_->RecoverAfterCrashAt("host-a", NowS() + 3600.0).ok());
  h = store_->History(again.id);
  ASSERT_TRUE(h.ok());
  EXPECT_LT((*h)[h->size() - 2].at_unix_s, NowS() + 1.0);
}

TEST_P(LabStoreTest, HostsAreListedWithTheirBenchesAndHeartbeats) {
  auto b = Open();
  const double t0 = NowS();
  ASSERT_TRUE(b->Heartbeat(HostRecord{"host-b", "10.0.0.2:50051", R"([{"name":"emu-1"}])", t0 - 5, 0}, 10, {}).ok());
  ASSERT_TRUE(store_->Heartbeat(HostRecord{"host-a", "10.0.0.1:50051", R"([{"name":"emu-2"}])", t0 - 9, 0}, 10, {}).ok());
  std::this_thread::sleep_for(20ms);
  ASSERT_TRUE(b->Heartbeat(HostRecord{"host-b", "10.0.0.2:50052", R"([{"name":"emu-1"},{"name":"emu-3"}])", t0 - 5, 0},
                           10, {}).ok());
  auto hosts = store_->ListHosts();
  ASSERT_TRUE(hosts.ok()) << hosts.status().ToString();
  ASSERT_EQ(hosts->size(), 2u);
  EXPECT_EQ((*hosts)[0].name, "host-a");
  EXPECT_EQ((*hosts)[0].address, "10.0.0.1:50051");
  EXPECT_EQ((*hosts)[0].benches_json, R"([{"name":"emu-2"}])");
  EXPECT_DOUBLE_EQ((*hosts)[0].started_unix_s, t0 - 9);
  EXPECT_EQ((*hosts)[1].name, "host-b");
  EXPECT_EQ((*hosts)[1].address, "10.0.0.2:50052");  // the latest heartbeat's
  EXPECT_EQ((*hosts)[1].benches_json, R"([{"name":"emu-1"},{"name":"emu-3"}])");
  EXPECT_GT((*hosts)[1].heartbeat_unix_s, (*hosts)[0].heartbeat_unix_s);
  EXPECT_GE((*hosts)[0].heartbeat_unix_s, t0 - 1);
  EXPECT_LE((*hosts)[1].heartbeat_unix_s, NowS() + 1);
}

TEST_P(LabStoreTest, ANightIsClaimedByExactlyOneHostAcrossConnections) {
  constexpr int kHosts = 6;
  std::vector<std::unique_ptr<Store>> hosts;
  for (int k = 0; k < kHosts; ++k) hosts.push_back(Open());
  std::atomic<int> winners{0}, errors{0};
  std::atomic<bool> go{false};
  std::vector<std::thread> threads;
  for (int k = 0; k < kHosts; ++k) {
    threads.emplace_back([&, k] {
      while (!go.load()) std::this_thread::yield();
      auto won = hosts[k]->ClaimNight("2026-11-25", Cat("host-", k));
      if (!won.ok()) ++errors;
      else if (*won) ++winners;
    });
  }
  go.store(true);
  for (auto& t : threads) t.join();
  EXPECT_EQ(errors.load(), 0);
  EXPECT_EQ(winners.load(), 1);
  // Later callers, the winner included, do not get it again; another night is a new claim.
  for (int k = 0; k < kHosts; ++k) EXPECT_FALSE(*hosts[k]->ClaimNight("2026-11-25", Cat("host-", k)));
  EXPECT_TRUE(*store_->ClaimNight("2026-11-26", "host-0"));
  auto bad = store_->ClaimNight("tonight", "host-0");
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find("night"), std::string::npos);
  EXPECT_EQ(store_->ClaimNight("2026-11-27", "").status().code(), StatusCode::kInvalidArgument);
}

// Many claimers on several connections with leases: every run is claimed by exactly one of them.
TEST_P(LabStoreTest, ConcurrentHostsNeverClaimTheSameRun) {
  const auto ids = SubmitRuns(120);
  constexpr int kHosts = 4;
  std::vector<std::vector<std::int64_t>> got(kHosts);
  std::vector<std::thread> threads;
  for (int k = 0; k < kHosts; ++k) {
    threads.emplace_back([&, k] {
      auto s = Open();
      while (true) {
        auto c = s->ClaimNext(Claim(Cat("host-", k), Cat("bench-", k), 30.0, 1.0));
        if (!c.ok() || !c->has_value()) break;
        got[k].push_back((*c)->id);
        EXPECT_TRUE(s->Finish(LeaseOf(**c), RunStatus::kDone, "", {}).ok());
      }
    });
  }
  for (auto& t : threads) t.join();
  std::vector<std::int64_t> all;
  for (const auto& g : got) all.insert(all.end(), g.begin(), g.end());
  std::sort(all.begin(), all.end());
  EXPECT_EQ(all, ids);
  std::int64_t stale = -1;
  ASSERT_TRUE(store_->StaleWrites(1, &stale).ok());
  EXPECT_EQ(stale, 0);
}

INSTANTIATE_TEST_SUITE_P(Engines, LabStoreTest, ::testing::ValuesIn(LabStoreEngines()),
                         [](const ::testing::TestParamInfo<Engine>& info) { return info.param.name; });

}  // namespace
}  // namespace vb::db
