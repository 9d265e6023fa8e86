// The lab's store methods on PostgreSQL (docs/store.md, "PostgreSQL"; docs/lab.md): claims from many
// connections never duplicate, SKIP LOCKED passes over a locked run without waiting, fencing refuses a stale
// lease and records it, lapsed leases are re-queued (once, with two reapers at once), aging, one night per lab,
// hosts; and the PostgreSQL schema machinery (concurrent first opens, a newer version, a foreign database).
// The same lab tests on SQLite are tests/db/lab_store_test.cc.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <map>
#include <set>
#include <thread>

#include "db/open_store.h"
#include "db/pg_conn.h"
#include "db/pg_schema.h"
#include "db/store.h"
#include "db/text.h"
#include "tests/db/pg_server.h"
#include "tests/db/store_engines.h"

namespace vb::db {
namespace {

using testing::StoreEngineTest;

RunRecord MakeRun(const std::string& name, std::int32_t priority = 0) {
  RunRecord r;
  r.key = NamedRun(name);
  r.controller = "pi_current";
  r.bench_kind = "emulated";
  r.spec_json = Cat("{\"name\": \"", name, "\"}");
  r.priority = priority;
  return r;
}

std::vector<std::int64_t> Submit(Store& store, std::vector<RunRecord> runs) {
  std::vector<std::int64_t> ids;
  auto b = store.SubmitBatch("alice", "batch", "{}", std::move(runs), &ids);
  EXPECT_TRUE(b.ok()) << b.status().ToString();
  return ids;
}

ClaimRequest HostClaim(const std::string& host, double ttl_s, double aging_s = 0) {
  ClaimRequest r = BenchClaim("emulated", "bench-" + host);
  r.host = host;
  r.lease_ttl_s = ttl_s;
  r.aging_s = aging_s;
  return r;
}

RunRecord ClaimOrDie(Store& store, const ClaimRequest& request) {
  auto c = store.ClaimNext(request);
  EXPECT_TRUE(c.ok()) << c.status().ToString();
  if (!c.ok() || !c->has_value()) {
    ADD_FAILURE() << "nothing claimed";
    return RunRecord();
  }
  return **c;
}

TraceChunk Chunk(std::int32_t index) {
  TraceChunk c;
  c.index = index;
  c.t0_s = index * 0.1;
  c.sample_period_s = 1e-3;
  c.samples = 100;
  c.channels = {"i_A", "x_m"};
  c.data.resize(200);
  for (std::size_t k = 0; k < c.data.size(); ++k) c.data[k] = std::sin(0.01 * static_cast<double>(k + index));
  return c;
}

void SleepS(double s) { std::this_thread::sleep_for(std::chrono::duration<double>(s)); }

class PgLabTest : public StoreEngineTest {};

TEST_P(PgLabTest, ManyConnectionsClaimEveryRunExactlyOnce) {
  constexpr int kRuns = 120, kThreads = 4;
  std::vector<RunRecord> runs;
  for (int k = 0; k < kRuns; ++k) runs.push_back(MakeRun(Cat("r", k), k % 3));
  const auto ids = Submit(store(), runs);
  ASSERT_EQ(ids.size(), static_cast<std::size_t>(kRuns));

  std::vector<std::vector<std::int64_t>> got(kThreads);
  std::vector<std::thread> threads;
  std::atomic<int> errors{0};
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      auto s = OpenStore(location());  // a connection per thread, as hosts have
      if (!s.ok()) {
        ++errors;
        return;
      }
      while (true) {
        auto c = (*s)->ClaimNext(HostClaim(Cat("h", t), 30));
        if (!c.ok()) {
          ++errors;
          return;
        }
        if (!c->has_value()) return;
        if ((*c)->fence != 1 || (*c)->host != Cat("h", t) || (*c)->status != RunStatus::kRunning) ++errors;
        got[static_cast<std::size_t>(t)].push_back((*c)->id);
      }
    });
  }
  for (auto& th : threads) th.join();
  EXPECT_EQ(errors.load(), 0);
  std::vector<std::int64_t> all;
  for (const auto& g : got) all.insert(all.end(), g.begin(), g.end());
  std::sort(all.begin(), all.end());
  EXPECT_EQ(all, ids);  // every run once: none twice, none missed
  int busy_threads = 0;
  for (const auto& g : got) busy_threads += !g.empty();
  EXPECT_GE(busy_threads, 2) << "the claims did not overlap at all";
  auto queued = store().CountQueued("");
  ASSERT_TRUE(queued.ok());
  EXPECT_EQ(*queued, 0);
}

TEST_P(PgLabTest, SkipLockedPassesOverALockedRunWithoutWaiting) {
  const auto ids = Submit(store(), {MakeRun("first", 5), MakeRun("second", 1)});
  // Another host is in the middle of claiming "first": its row is locked.
  auto other = pg::Connection::Open(location());
  ASSERT_TRUE(other.ok()) << other.status().ToString();
  ASSERT_TRUE((*other)->Script("BEGIN").ok());
  auto locked = (*other)->Exec("SELECT id FROM runs WHERE id = $1 FOR UPDATE", pg::Params().Int(ids[0]));
  ASSERT_TRUE(locked.ok()) << locked.status().ToString();

  const auto t0 = std::chrono::steady_clock::now();
  RunRecord got = ClaimOrDie(store(), HostClaim("b", 10));
  const double waited_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(got.id, ids[1]);  // the lower-priority run, at once
  EXPECT_LT(waited_s, 2.0);
  auto none = store().ClaimNext(HostClaim("b", 10));
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->has_value());  // the locked run is skipped, not waited for

  ASSERT_TRUE((*other)->Script("ROLLBACK").ok());
  EXPECT_EQ(ClaimOrDie(store(), HostClaim("b", 10)).id, ids[0]);
}

TEST_P(PgLabTest, FencingRefusesAStaleLeaseAndRecordsIt) {
  const auto ids = Submit(store(), {MakeRun("r")});
  RunRecord a = ClaimOrDie(store(), HostClaim("a", 0.2));
  EXPECT_EQ(a.fence, 1);
  EXPECT_GT(a.lease_expires_unix_s, a.started_unix_s);
  ASSERT_TRUE(store().AppendTraceChunk(LeaseOf(a), Chunk(0)).ok());
  SleepS(0.4);  // host a stops heartbeating; its lease lapses
  auto lapsed = store().RequeueLapsed();
  ASSERT_TRUE(lapsed.ok()) << lapsed.status().ToString();
  EXPECT_EQ(*lapsed, std::vector<std::int64_t>{ids[0]});
  RunRecord b = ClaimOrDie(store(), HostClaim("b", 30));
  EXPECT_EQ(b.id, a.id);
  EXPECT_EQ(b.fence, 2);
  EXPECT_EQ(b.host, "b");
  ASSERT_TRUE(store().SetProgress(LeaseOf(b), 0.25).ok());

  // Host a wakes up and carries on with its old lease: every write is refused and logged.
  const Status progress = store().SetProgress(LeaseOf(a), 0.9);
  EXPECT_EQ(progress.code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(progress.message().rfind("stale write", 0), 0u) << progress.message();
  const Status chunk = store().AppendTraceChunk(LeaseOf(a), Chunk(0));
  EXPECT_EQ(chunk.code(), StatusCode::kFailedPrecondition) << chunk.ToString();
  const Status finish = store().Finish(LeaseOf(a), RunStatus::kDone, "", {{"rmse_A", 1.0}});
  EXPECT_EQ(finish.code(), StatusCode::kFailedPrecondition) << finish.ToString();

  auto run = store().GetRun(a.id);
  ASSERT_TRUE(run.ok());
  EXPECT_EQ(run->status, RunStatus::kRunning);
  EXPECT_EQ(run->host, "b");
  EXPECT_EQ(run->progress, 0.25);
  auto trace = store().ReadTrace(a.id);
  ASSERT_TRUE(trace.ok());
  EXPECT_TRUE(trace->empty());  // a's partial trace went with the requeue; its late chunk was refused
  auto metrics = store().GetMetrics(a.id);
  ASSERT_TRUE(metrics.ok());
  EXPECT_TRUE(metrics->empty());

  std::int64_t total = 0;
  auto stale = store().StaleWrites(10, &total);
  ASSERT_TRUE(stale.ok()) << stale.status().ToString();
  EXPECT_EQ(total, 3);
  ASSERT_EQ(stale->size(), 3u);
  EXPECT_EQ((*stale)[0].what, "progress");
  EXPECT_EQ((*stale)[1].what, "trace chunk 0");
  EXPECT_EQ((*stale)[2].what, "finish done");
  for (const StaleWrite& w : *stale) {
    EXPECT_EQ(w.run_id, a.id);
    EXPECT_EQ(w.fence, 1);
    EXPECT_EQ(w.current_fence, 2);
    EXPECT_EQ(w.host, "b");
    EXPECT_GT(w.at_unix_s, 0);
  }
  auto one = store().StaleWrites(1, nullptr);
  ASSERT_TRUE(one.ok());
  EXPECT_EQ(one->size(), 1u);
  EXPECT_EQ(store().StaleWrites(0, nullptr).status().code(), StatusCode::kInvalidArgument);

  // The current holder finishes normally; a second, different Finish with its own (now finished) lease is
  // stale too. The same Finish again is a retry whose first try committed (its answer lost): Ok, nothing added.
  ASSERT_TRUE(store().Finish(LeaseOf(b), RunStatus::kDone, "", {{"rmse_A", 0.5}}).ok());
  const Status again = store().Finish(LeaseOf(b), RunStatus::kFailed, "late", {});
  EXPECT_EQ(again.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(again.message().find("is done, not running"), std::string::npos) << again.message();
  EXPECT_TRUE(store().Finish(LeaseOf(b), RunStatus::kDone, "", {{"rmse_A", 0.5}}).ok());
  EXPECT_EQ(store().GetMetrics(b.id)->size(), 1u);
}

TEST_P(PgLabTest, HeartbeatsKeepALeaseAndLapsedOnesAreRequeued) {
  const auto ids = Submit(store(), {MakeRun("kept"), MakeRun("lapses")});
  RunRecord kept = ClaimOrDie(store(), HostClaim("alive", 0.3));
  RunRecord lapses = ClaimOrDie(store(), HostClaim("dead", 0.3));
  ASSERT_TRUE(store().AppendTraceChunk(LeaseOf(lapses), Chunk(0)).ok());
  auto none = store().RequeueLapsed();
  ASSERT_TRUE(none.ok());
  EXPECT_TRUE(none->empty());
  for (int k = 0; k < 4; ++k) {
    SleepS(0.15);
    HostRecord h;
    h.name = "alive";
    h.address = "10.0.0.1:50051";
    h.benches_json = "[{\"name\":\"bench-alive\"}]";
    ASSERT_TRUE(store().Heartbeat(h, 0.3, {LeaseOf(kept)}).ok());
  }
  auto lapsed = store().RequeueLapsed();
  ASSERT_TRUE(lapsed.ok()) << lapsed.status().ToString();
  EXPECT_EQ(*lapsed, std::vector<std::int64_t>{lapses.id});

  auto k = store().GetRun(kept.id);
  ASSERT_TRUE(k.ok());
  EXPECT_EQ(k->status, RunStatus::kRunning);
  auto l = store().GetRun(lapses.id);
  ASSERT_TRUE(l.ok());
  EXPECT_EQ(l->status, RunStatus::kQueued);
  EXPECT_EQ(l->host, "");
  EXPECT_EQ(l->lease_expires_unix_s, 0);
  EXPECT_EQ(l->bench_name, "");  // the bench it asked for (any), not the one that ran it
  auto trace = store().ReadTrace(lapses.id);
  ASSERT_TRUE(trace.ok());
  EXPECT_TRUE(trace->empty());
  auto h = store().History(lapses.id);
  ASSERT_TRUE(h.ok());
  ASSERT_EQ(h->size(), 4u);
  EXPECT_EQ((*h)[2].status, RunStatus::kInterrupted);
  EXPECT_NE((*h)[2].reason.find("dead"), std::string::npos) << (*h)[2].reason;
  EXPECT_EQ((*h)[3].status, RunStatus::kQueued);
  (void)ids;

  auto hosts = store().ListHosts();
  ASSERT_TRUE(hosts.ok());
  ASSERT_EQ(hosts->size(), 1u);
  EXPECT_EQ((*hosts)[0].name, "alive");
  EXPECT_EQ((*hosts)[0].address, "10.0.0.1:50051");
  EXPECT_GT((*hosts)[0].heartbeat_unix_s, 0);
  EXPECT_GE((*hosts)[0].heartbeat_unix_s, (*hosts)[0].started_unix_s);
}

TEST_P(PgLabTest, TwoReapersAtOnceHandleEachLapsedRunOnce) {
  constexpr int kRuns = 30;
  std::vector<RunRecord> runs;
  for (int k = 0; k < kRuns; ++k) runs.push_back(MakeRun(Cat("r", k)));
  Submit(store(), runs);
  for (int k = 0; k < kRuns; ++k) ClaimOrDie(store(), HostClaim("gone", 0.05));
  SleepS(0.2);
  std::vector<std::int64_t> got[2];
  std::vector<std::thread> threads;
  for (int t = 0; t < 2; ++t) {
    threads.emplace_back([&, t] {
      auto s = OpenStore(location());
      if (!s.ok()) return;
      for (int rounds = 0; rounds < 3; ++rounds) {
        auto ids = (*s)->RequeueLapsed();
        if (ids.ok()) got[t].insert(got[t].end(), ids->begin(), ids->end());
      }
    });
  }
  for (auto& th : threads) th.join();
  std::multiset<std::int64_t> all(got[0].begin(), got[0].end());
  all.insert(got[1].begin(), got[1].end());
  EXPECT_EQ(all.size(), static_cast<std::size_t>(kRuns));
  EXPECT_EQ(std::set<std::int64_t>(all.begin(), all.end()).size(), static_cast<std::size_t>(kRuns));
  auto list = store().ListRuns(RunFilter{});
  ASSERT_TRUE(list.ok());
  for (const RunRecord& r : *list) {
    auto h = store().History(r.id);
    ASSERT_TRUE(h.ok());
    EXPECT_EQ(
        std::count_if(h->begin(), h->end(), [](const StatusChange& c) { return c.status == RunStatus::kInterrupted; }),
        1);
    EXPECT_EQ(r.status, RunStatus::kQueued);
  }
}

TEST_P(PgLabTest, ARunWhoseLeaseLapsesThreeTimesIsFailedAsPoison) {
  const auto ids = Submit(store(), {MakeRun("poison")});
  for (int k = 1; k <= 3; ++k) {
    RunRecord r = ClaimOrDie(store(), HostClaim("h", 0.05));
    EXPECT_EQ(r.fence, k);
    SleepS(0.1);
    auto lapsed = store().RequeueLapsed();
    ASSERT_TRUE(lapsed.ok());
    EXPECT_EQ(lapsed->size(), 1u);
  }
  auto run = store().GetRun(ids[0]);
  ASSERT_TRUE(run.ok());
  EXPECT_EQ(run->status, RunStatus::kFailed);
  EXPECT_NE(run->reason.find("3 times"), std::string::npos) << run->reason;
}

TEST_P(PgLabTest, AgingLetsAnOldLowPriorityRunOvertake) {
  const auto old_ids = Submit(store(), {MakeRun("old", 0)});
  SleepS(0.5);
  const auto new_ids = Submit(store(), {MakeRun("new", 2)});
  // Without aging, priority decides.
  auto c = store().ClaimNext(HostClaim("h", 0));
  ASSERT_TRUE(c.ok() && c->has_value());
  EXPECT_EQ((*c)->id, new_ids[0]);
  ASSERT_TRUE(store().RequestCancel(old_ids[0], "x").ok());

  const auto ids2 = Submit(store(), {MakeRun("old2", 0)});
  SleepS(0.5);
  const auto new2 = Submit(store(), {MakeRun("new2", 2)});
  // aging_s = 0.1: the old run has waited >= 5 periods (effective priority >= 5) and the new one none (2).
  RunRecord first = ClaimOrDie(store(), HostClaim("h", 0, 0.1));
  EXPECT_EQ(first.id, ids2[0]);
  RunRecord second = ClaimOrDie(store(), HostClaim("h", 0, 0.1));
  EXPECT_EQ(second.id, new2[0]);
  EXPECT_EQ(store().ClaimNext(HostClaim("h", -1)).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store().ClaimNext(HostClaim("h", 0, std::nan(""))).status().code(), StatusCode::kInvalidArgument);
}

TEST_P(PgLabTest, ANightIsClaimedByExactlyOneHost) {
  std::atomic<int> winners{0}, errors{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      auto s = OpenStore(location());
      if (!s.ok()) {
        ++errors;
        return;
      }
      auto won = (*s)->ClaimNight("2026-11-25", Cat("host", t));
      if (!won.ok())
        ++errors;
      else if (*won)
        ++winners;
    });
  }
  for (auto& th : threads) th.join();
  EXPECT_EQ(errors.load(), 0);
  EXPECT_EQ(winners.load(), 1);
  auto again = store().ClaimNight("2026-11-25", "late");
  ASSERT_TRUE(again.ok());
  EXPECT_FALSE(*again);
  auto next = store().ClaimNight("2026-11-26", "late");
  ASSERT_TRUE(next.ok());
  EXPECT_TRUE(*next);
  const Status bad = store().ClaimNight("25/11/2026", "h").status();
  EXPECT_EQ(bad.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad.message().find("night:"), std::string::npos);
}

TEST_P(PgLabTest, HeartbeatChecksItsInputAndUsesTheDatabaseClock) {
  HostRecord h;
  EXPECT_EQ(store().Heartbeat(h, 10, {}).code(), StatusCode::kInvalidArgument);
  h.name = "a";
  const Status bad_ttl = store().Heartbeat(h, -1, {});
  EXPECT_EQ(bad_ttl.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad_ttl.message().find("lease_ttl_s"), std::string::npos);
  ASSERT_TRUE(store().Heartbeat(h, 10, {}).ok());
  auto first = store().ListHosts();
  ASSERT_TRUE(first.ok());
  ASSERT_EQ(first->size(), 1u);
  EXPECT_EQ((*first)[0].benches_json, "[]");
  SleepS(0.05);
  ASSERT_TRUE(store().Heartbeat(h, 10, {}).ok());
  auto second = store().ListHosts();
  ASSERT_TRUE(second.ok());
  EXPECT_GT((*second)[0].heartbeat_unix_s, (*first)[0].heartbeat_unix_s);
  const double now = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  EXPECT_NEAR((*second)[0].heartbeat_unix_s, now, 60);  // the database's clock: this machine's, here
}

TEST_P(PgLabTest, RecoverAfterCrashTouchesOnlyItsOwnHostsRuns) {
  Submit(store(), {MakeRun("a"), MakeRun("b")});
  RunRecord a = ClaimOrDie(store(), HostClaim("a", 30));
  RunRecord b = ClaimOrDie(store(), HostClaim("b", 30));
  auto n = store().RecoverAfterCrash("a");
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(*n, 1);
  EXPECT_EQ(store().GetRun(a.id)->status, RunStatus::kQueued);
  EXPECT_EQ(store().GetRun(b.id)->status, RunStatus::kRunning);
}

TEST_P(PgLabTest, AConnectionTheServerDroppedIsRemadeOnTheNextCall) {
  Submit(store(), {MakeRun("a")});
  ASSERT_TRUE(store().CountQueued("").ok());  // the store's connection is up
  auto admin = pg::Connection::Open(location());
  ASSERT_TRUE(admin.ok());
  // As a restarted or failed-over database server does: every other session on the database ends.
  auto killed = (*admin)->QueryInt(
      "SELECT count(*) FROM (SELECT pid FROM pg_stat_activity WHERE datname = current_database() AND "
      "pid <> pg_backend_pid() OFFSET 0) AS others WHERE pg_terminate_backend(pid, 5000)");  // OFFSET 0: filter first
  ASSERT_TRUE(killed.ok()) << killed.status().ToString();
  ASSERT_GE(*killed, 1);
  // The first call after the sessions ended already runs on a new connection (issue 30: it used to fail).
  auto first = store().CountQueued("");
  EXPECT_TRUE(first.ok()) << first.status().ToString();
  auto second = store().CountQueued("");
  ASSERT_TRUE(second.ok()) << second.status().ToString();
  EXPECT_EQ(*second, 1);
  // Transactions work again too: a claim, and a write under its lease.
  RunRecord r = ClaimOrDie(store(), HostClaim("h", 10));
  EXPECT_TRUE(store().SetProgress(LeaseOf(r), 0.5).ok());
}

TEST_P(PgLabTest, HostsSavingABaselineUnderOneNameAtOnceGetSuccessiveVersions) {
  constexpr int kHosts = 4;
  std::vector<std::int32_t> versions(kHosts, 0);
  std::vector<std::string> errors(kHosts);
  std::vector<std::thread> threads;
  for (int t = 0; t < kHosts; ++t) {
    threads.emplace_back([&, t] {
      auto s = OpenStore(location());
      if (!s.ok()) {
        errors[static_cast<std::size_t>(t)] = s.status().ToString();
        return;
      }
      auto v = (*s)->SaveBaseline("main", Cat("host ", t), "", {{"case", "rmse_A", 1.0 + t, 0.0, 1}});
      if (v.ok())
        versions[static_cast<std::size_t>(t)] = *v;
      else
        errors[static_cast<std::size_t>(t)] = v.status().ToString();
    });
  }
  for (auto& th : threads) th.join();
  for (const std::string& e : errors) EXPECT_EQ(e, "");
  std::sort(versions.begin(), versions.end());
  EXPECT_EQ(versions, (std::vector<std::int32_t>{1, 2, 3, 4}));
  auto listed = store().ListBaselines();
  ASSERT_TRUE(listed.ok());
  EXPECT_EQ(listed->size(), static_cast<std::size_t>(kHosts));
}

// ---- The schema machinery on PostgreSQL ----

TEST_P(PgLabTest, SchemaIsAtTheCurrentVersionAndReopeningKeepsIt) {
  EXPECT_EQ(store().schema_version(), pg_schema::CurrentVersion());
  EXPECT_EQ(pg_schema::CurrentVersion(), 7);
  Submit(store(), {MakeRun("kept")});
  auto again = OpenAnother();
  ASSERT_NE(again, nullptr);
  EXPECT_EQ(again->schema_version(), 7);
  auto runs = again->ListRuns(RunFilter{});
  ASSERT_TRUE(runs.ok());
  EXPECT_EQ(runs->size(), 1u);
}

TEST_P(PgLabTest, RefusesANewerSchemaWithoutTouchingTheDatabase) {
  auto raw = pg::Connection::Open(location());
  ASSERT_TRUE(raw.ok());
  ASSERT_TRUE((*raw)->Script("UPDATE schema_version SET version = 99").ok());
  auto refused = OpenStore(location());
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(refused.status().message().find("99"), std::string::npos) << refused.status().message();
  auto v = (*raw)->QueryInt("SELECT version FROM schema_version");
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(*v, 99);
}

TEST_P(PgLabTest, ConcurrentFirstOpensMigrateOnceAndAFailingMigrationChangesNothing) {
  testing::PgServer* server = testing::PgServer::Get();
  ASSERT_NE(server, nullptr);
  auto fresh = server->CreateDatabase();
  ASSERT_TRUE(fresh.ok());
  std::atomic<int> ok{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&] {
      auto s = OpenStore(*fresh);
      if (s.ok() && (*s)->schema_version() == pg_schema::CurrentVersion())
        ++ok;
      else if (!s.ok())
        ADD_FAILURE() << s.status().ToString();
    });
  }
  for (auto& th : threads) th.join();
  EXPECT_EQ(ok.load(), 4);

  // A migration list whose last step fails: the database stays as it was (the current version, no new table).
  const int now = pg_schema::CurrentVersion();
  auto conn = pg::Connection::Open(*fresh);
  ASSERT_TRUE(conn.ok());
  std::vector<pg_schema::Migration> more(pg_schema::Migrations().begin(), pg_schema::Migrations().end());
  more.push_back({now + 1, "a good step", "CREATE TABLE extra (x int)"});
  more.push_back({now + 2, "a bad step", "CREATE TABLE broken (x no_such_type)"});
  auto migrated = pg_schema::Migrate(conn->get(), more);
  ASSERT_FALSE(migrated.ok());
  EXPECT_NE(migrated.status().message().find(Cat("version ", now + 2)), std::string::npos)
      << migrated.status().message();
  auto v = pg_schema::ReadVersion(conn->get());
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(*v, now);
  auto extra = (*conn)->QueryInt("SELECT (to_regclass('extra') IS NULL)::int::int8");
  ASSERT_TRUE(extra.ok());
  EXPECT_EQ(*extra, 1);
}

// A lab database at version 5 (before runs kept what executing them measured) migrates to version 6 with its
// runs as they were: no execution record is made up for them, and a run finished after the upgrade keeps its own.
TEST_P(PgLabTest, AVersion5DatabaseMigratesKeepingItsRuns) {
  testing::PgServer* server = testing::PgServer::Get();
  ASSERT_NE(server, nullptr);
  auto fresh = server->CreateDatabase();
  ASSERT_TRUE(fresh.ok());
  {
    auto conn = pg::Connection::Open(*fresh);
    ASSERT_TRUE(conn.ok());
    std::vector<pg_schema::Migration> v5(pg_schema::Migrations().begin(), pg_schema::Migrations().begin() + 5);
    auto v = pg_schema::Migrate(conn->get(), v5);
    ASSERT_TRUE(v.ok()) << v.status().ToString();
    ASSERT_EQ(*v, 5);
    const char* rows =
        "INSERT INTO batches (id, submitter, name, spec_json, created) VALUES (1, 'u', 'b', '{}', 0);"
        "INSERT INTO runs (id, batch_id, name, controller, bench_kind, requested_bench, bench_name, spec_json, "
        "submitter, priority, status, requeue_on_interrupt, submitted, key_name) VALUES "
        "(1, 1, 'old', 'pi_current', 'emulated', '', 'bench-1', '{}', 'u', 0, 'done', true, 0, 'old'),"
        "(2, 1, 'new', 'pi_current', 'emulated', '', '', '{}', 'u', 0, 'queued', true, 0, 'new');"
        "SELECT setval(pg_get_serial_sequence('runs', 'id'), 2);"
        "SELECT setval(pg_get_serial_sequence('batches', 'id'), 1);";
    ASSERT_TRUE((*conn)->Script(rows).ok());
  }
  auto s = OpenStore(*fresh);
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_EQ((*s)->schema_version(), pg_schema::CurrentVersion());
  auto old = (*s)->GetRun(1);
  ASSERT_TRUE(old.ok()) << old.status().ToString();
  EXPECT_EQ(old->status, RunStatus::kDone);
  EXPECT_EQ(old->key.name, "old");
  EXPECT_FALSE(old->execution.has_value());
  auto claimed = (*s)->ClaimNext(BenchClaim("emulated", "bench-1"));
  ASSERT_TRUE(claimed.ok() && claimed->has_value());
  ASSERT_EQ((*claimed)->id, 2);
  ExecutionRecord e;
  e.wall_s = 2.0;
  e.loop.emplace();
  e.loop->ticks = 4;
  e.loop->jitter_max_s = 3e-4;
  ASSERT_TRUE((*s)->Finish(LeaseOf(**claimed), RunStatus::kDone, "", {}, e).ok());
  auto reopened = OpenStore(*fresh);
  ASSERT_TRUE(reopened.ok());
  auto fresh_run = (*reopened)->GetRun(2);
  ASSERT_TRUE(fresh_run.ok() && fresh_run->execution && fresh_run->execution->loop);
  EXPECT_EQ(fresh_run->execution->wall_s, 2.0);
  EXPECT_EQ(fresh_run->execution->loop->jitter_max_s, 3e-4);
}

TEST_P(PgLabTest, RefusesSomebodyElsesDatabase) {
  testing::PgServer* server = testing::PgServer::Get();
  ASSERT_NE(server, nullptr);
  auto fresh = server->CreateDatabase();
  ASSERT_TRUE(fresh.ok());
  auto conn = pg::Connection::Open(*fresh);
  ASSERT_TRUE(conn.ok());
  ASSERT_TRUE((*conn)->Script("CREATE TABLE invoices (id int)").ok());
  auto refused = OpenStore(*fresh);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(refused.status().message().find("not a valvebench database"), std::string::npos);
  auto untouched = (*conn)->QueryInt("SELECT (to_regclass('schema_version') IS NULL)::int::int8");
  ASSERT_TRUE(untouched.ok());
  EXPECT_EQ(*untouched, 1);
}

TEST(PgLocationTest, ConnectionStringsAreRecognisedAndPasswordsNeverShown) {
  EXPECT_TRUE(IsPostgresLocation("postgresql://u:secret@db.lab/vb"));
  EXPECT_TRUE(IsPostgresLocation("postgres://db.lab/vb"));
  EXPECT_TRUE(IsPostgresLocation("host=/run/postgresql dbname=lab"));
  EXPECT_TRUE(IsPostgresLocation("dbname=lab"));
  EXPECT_FALSE(IsPostgresLocation("/var/lib/valvebench/store.db"));
  EXPECT_FALSE(IsPostgresLocation(":memory:"));
  EXPECT_FALSE(IsPostgresLocation("weird=name.db"));  // not a libpq keyword: a SQLite file
  EXPECT_EQ(pg::DescribeLocation("postgresql://u:secret@db.lab:5433/vb").find("secret"), std::string::npos);
  EXPECT_NE(pg::DescribeLocation("postgresql://u:secret@db.lab:5433/vb").find("'vb'"), std::string::npos);
  // Nothing listens there: Unavailable, naming the database, not the password.
  auto s = OpenStore("host=/nonexistent-vb-socket-dir dbname=lab password=hunter2");
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), StatusCode::kUnavailable);
  EXPECT_EQ(s.status().message().find("hunter2"), std::string::npos) << s.status().message();
  EXPECT_NE(s.status().message().find("lab"), std::string::npos) << s.status().message();
}

INSTANTIATE_TEST_SUITE_P(Engines, PgLabTest, ::testing::Values(std::string("postgresql")), testing::EngineName);

}  // namespace
}  // namespace vb::db
