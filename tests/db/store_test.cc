// The SQLite store: schema and migrations, the queue (order, filtering, exactly-once claims across
// connections), status history, cancel, crash recovery (including a SIGKILLed writer process), atomicity under
// injected faults, background checkpoints, listing, traces (bit-exact) and bad input.
#include <gtest/gtest.h>
#include <signal.h>
#include <sqlite3.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <set>
#include <thread>

#include "db/checkpointer.h"
#include "db/open_store.h"
#include "db/schema.h"
#include "db/sqlite_store.h"
#include "db/store.h"
#include "db/testing.h"
#include "db/text.h"
#include "tests/db/store_engines.h"

namespace vb::db {
namespace {

// ---- helpers ----

void RemoveDbFiles(const std::string& path) {
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) std::remove((path + suffix).c_str());
}

// Removes the test databases when the tests are over.
class TempDbFiles : public ::testing::Environment {
 public:
  static std::vector<std::string>& Paths() {
    static std::vector<std::string> paths;
    return paths;
  }
  void TearDown() override {
    for (const std::string& p : Paths()) RemoveDbFiles(p);
  }
};
[[maybe_unused]] ::testing::Environment* const kTempDbFiles = ::testing::AddGlobalTestEnvironment(new TempDbFiles);

// A fresh database path under the test temp dir (old files from an earlier run removed).
std::string TempDb(const std::string& name) {
  const std::string path = Cat(::testing::TempDir(), "vb_store_test_", name, "_", getpid(), ".db");
  RemoveDbFiles(path);
  TempDbFiles::Paths().push_back(path);
  return path;
}

std::string ReadFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

bool FileExists(const std::string& path) { return access(path.c_str(), F_OK) == 0; }

std::unique_ptr<Store> OpenOrDie(const std::string& path) {
  auto s = OpenSqliteStore(path);
  EXPECT_TRUE(s.ok()) << s.status().ToString();
  return s.ok() ? std::move(s).value() : nullptr;
}

RunRecord MakeRun(const std::string& name, std::int32_t priority = 0, const std::string& bench_kind = "emulated",
                  const std::string& bench_name = "", std::vector<std::string> tags = {}) {
  RunRecord r;
  r.key = NamedRun(name);
  r.controller = "pi_current";
  r.bench_kind = bench_kind;
  r.bench_name = bench_name;
  r.spec_json = Cat("{\"name\": \"", name, "\"}");
  r.priority = priority;
  r.tags = std::move(tags);
  return r;
}

// Submits the runs as one batch and returns their ids.
std::vector<std::int64_t> Submit(Store& store, std::vector<RunRecord> runs, const std::string& submitter = "alice",
                                 std::int64_t* batch_id = nullptr) {
  std::vector<std::int64_t> ids;
  auto b = store.SubmitBatch(submitter, "batch", "{\"batch\": true}", std::move(runs), &ids);
  EXPECT_TRUE(b.ok()) << b.status().ToString();
  if (batch_id != nullptr && b.ok()) *batch_id = *b;
  return ids;
}

std::int64_t ClaimId(Store& store, const std::string& kind = "emulated", const std::string& bench = "bench-1") {
  auto c = store.ClaimNext(db::BenchClaim(kind, bench));
  EXPECT_TRUE(c.ok()) << c.status().ToString();
  if (!c.ok() || !c->has_value()) return 0;
  return (*c)->id;
}

std::vector<RunStatus> HistoryStatuses(Store& store, std::int64_t id) {
  auto h = store.History(id);
  EXPECT_TRUE(h.ok()) << h.status().ToString();
  std::vector<RunStatus> out;
  if (h.ok()) {
    for (const auto& c : *h) out.push_back(c.status);
  }
  return out;
}

// Raw SQLite access for checks the Store API does not offer.
struct RawDb {
  explicit RawDb(const std::string& path) { EXPECT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK); }
  ~RawDb() { sqlite3_close(db); }
  std::int64_t Int(const std::string& sql) {
    sqlite3_stmt* st = nullptr;
    EXPECT_EQ(sqlite3_prepare_v2(db, sql.c_str(), -1, &st, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
    EXPECT_EQ(sqlite3_step(st), SQLITE_ROW) << sql;
    const std::int64_t v = sqlite3_column_int64(st, 0);
    sqlite3_finalize(st);
    return v;
  }
  std::string Text(const std::string& sql) {
    sqlite3_stmt* st = nullptr;
    EXPECT_EQ(sqlite3_prepare_v2(db, sql.c_str(), -1, &st, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
    EXPECT_EQ(sqlite3_step(st), SQLITE_ROW) << sql;
    const unsigned char* p = sqlite3_column_text(st, 0);
    std::string v = p ? reinterpret_cast<const char*>(p) : "";
    sqlite3_finalize(st);
    return v;
  }
  void Exec(const std::string& sql) {
    char* err = nullptr;
    EXPECT_EQ(sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &err), SQLITE_OK) << (err ? err : "");
    sqlite3_free(err);
  }
  sqlite3* db = nullptr;
};

TraceChunk MakeChunk(std::int32_t index, std::int32_t samples, const std::vector<std::string>& channels,
                     std::uint32_t seed) {
  TraceChunk c;
  c.index = index;
  c.t0_s = index * samples * 1e-4;
  c.sample_period_s = 1e-4;
  c.samples = samples;
  c.channels = channels;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1e3, 1e3);
  c.data.resize(channels.size() * static_cast<std::size_t>(samples));
  for (double& v : c.data) v = u(rng);
  return c;
}

// ---- tests on both engines (tests/db/store_engines.h) ----
// Everything below through the traces runs on SQLite and on PostgreSQL, except the suites marked SQLite-only:
// StoreSchemaTest (user_version, WAL, the file's bytes; PostgreSQL's schema machinery: pg_lab_test.cc),
// StoreCrashTest (a writer process killed mid-write: WAL recovery of the file) and CheckpointerTest.
class StoreRunKeyTest : public testing::StoreEngineTest {};
class StoreSubmitTest : public testing::StoreEngineTest {};
class StoreAtomicityTest : public testing::StoreEngineTest {};
class StoreQueueTest : public testing::StoreEngineTest {};
class StoreRunTest : public testing::StoreEngineTest {};
class StoreRecoveryTest : public testing::StoreEngineTest {};
class StoreConnectionsTest : public testing::StoreEngineTest {};
class StoreTraceTest : public testing::StoreEngineTest {};
#define VB_ENGINES(suite) \
  INSTANTIATE_TEST_SUITE_P(Engines, suite, ::testing::ValuesIn(testing::StoreEngines()), testing::EngineName)
VB_ENGINES(StoreRunKeyTest);
VB_ENGINES(StoreSubmitTest);
VB_ENGINES(StoreAtomicityTest);
VB_ENGINES(StoreQueueTest);
VB_ENGINES(StoreRunTest);
VB_ENGINES(StoreRecoveryTest);
VB_ENGINES(StoreConnectionsTest);
VB_ENGINES(StoreTraceTest);

// ---- status names ----

TEST(RunStatusTest, NamesRoundTrip) {
  for (RunStatus s : {RunStatus::kQueued, RunStatus::kRunning, RunStatus::kDone, RunStatus::kFailed,
                      RunStatus::kCancelled, RunStatus::kInterrupted}) {
    auto parsed = ParseRunStatus(RunStatusName(s));
    ASSERT_TRUE(parsed.ok());
    EXPECT_EQ(*parsed, s);
  }
  auto bad = ParseRunStatus("paused");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find("paused"), std::string::npos);
}

// ---- schema and migrations ----

TEST(StoreSchemaTest, NewDatabaseIsAtTheCurrentVersionInWalMode) {
  const std::string path = TempDb("schema");
  {
    auto store = OpenOrDie(path);
    ASSERT_NE(store, nullptr);
    EXPECT_EQ(store->schema_version(), schema::CurrentVersion());
    EXPECT_EQ(schema::CurrentVersion(), 7);  // v2: baselines and regressions; v3: run keys as fields; v4: codecs;
    // v5: the lab (fences, hosts, stale writes, nights claimed); v6: what executing a run measured; v7: its build
  }
  RawDb raw(path);
  EXPECT_EQ(raw.Int("PRAGMA user_version"), schema::CurrentVersion());
  EXPECT_EQ(raw.Text("PRAGMA journal_mode"), "wal");  // persistent in the file
  for (const char* table : {"batches", "runs", "run_tags", "status_history", "metrics", "trace_chunks", "baselines",
                            "baseline_metrics", "regressions"}) {
    EXPECT_EQ(raw.Int(Cat("SELECT count(*) FROM sqlite_schema WHERE type = 'table' AND name = '", table, "'")), 1)
        << table;
  }
  EXPECT_EQ(raw.Int("SELECT count(*) FROM sqlite_schema WHERE type = 'index' AND name = 'runs_queue'"), 1);
  EXPECT_EQ(raw.Int("SELECT count(*) FROM sqlite_schema WHERE type = 'index' AND name = 'run_tags_tag'"), 1);
}

TEST(StoreSchemaTest, InMemoryDatabaseWorks) {
  auto store = OpenOrDie(":memory:");
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(store->schema_version(), schema::CurrentVersion());
  auto ids = Submit(*store, {MakeRun("a")});
  ASSERT_EQ(ids.size(), 1u);
  EXPECT_EQ(ClaimId(*store), ids[0]);
}

TEST(StoreSchemaTest, ReopeningKeepsDataAndVersion) {
  const std::string path = TempDb("reopen");
  std::vector<std::int64_t> ids;
  {
    auto store = OpenOrDie(path);
    ids = Submit(*store, {MakeRun("a"), MakeRun("b")});
  }
  auto store = OpenOrDie(path);
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(store->schema_version(), schema::CurrentVersion());
  auto run = store->GetRun(ids[1]);
  ASSERT_TRUE(run.ok());
  EXPECT_EQ(run->key.name, "b");
}

TEST(StoreSchemaTest, MigrationsApplyInOrderAndKeepData) {
  const std::string path = TempDb("migrate");
  std::vector<std::int64_t> ids;
  {
    auto store = OpenOrDie(path);
    ids = Submit(*store, {MakeRun("kept")});
  }
  // A hypothetical next version on top of this build's list.
  const int next = schema::CurrentVersion() + 1;
  std::vector<schema::Migration> list(schema::Migrations().begin(), schema::Migrations().end());
  list.push_back({next, "add runs.note", "ALTER TABLE runs ADD COLUMN note TEXT NOT NULL DEFAULT 'n/a'"});
  auto conn = sql::Connection::Open(path);
  ASSERT_TRUE(conn.ok());
  auto v = schema::Migrate(&*conn, list, path);
  ASSERT_TRUE(v.ok()) << v.status().ToString();
  EXPECT_EQ(*v, next);
  RawDb raw(path);
  EXPECT_EQ(raw.Int("PRAGMA user_version"), next);
  EXPECT_EQ(raw.Text(Cat("SELECT note FROM runs WHERE id = ", ids[0])), "n/a");
  // Migrating again is a no-op.
  auto again = schema::Migrate(&*conn, list, path);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(*again, next);
}

TEST_P(StoreRunKeyTest, KeySplitAndStartTimeAreStoredAsFields) {
  Store* store = &this->store();
  ASSERT_NE(store, nullptr);
  RunRecord swept = MakeRun("m/pi");
  swept.key.sweep = {{"conditions.supply_V", 24.0}, {"bench.model.params[R]", 3.0000000001}};
  swept.key.repeat = 2;
  RunRecord imported = MakeRun("r07");
  imported.split = "holdout";
  imported.t_start_s = 12.5;
  auto ids = Submit(*store, {swept, imported});
  auto a = store->GetRun(ids[0]);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  EXPECT_EQ(a->key, swept.key);  // values exact, not re-read from 10-digit text
  EXPECT_EQ(a->split, "");
  EXPECT_TRUE(std::isnan(a->t_start_s));
  auto b = store->GetRun(ids[1]);
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->key, NamedRun("r07"));
  EXPECT_EQ(b->split, "holdout");
  EXPECT_EQ(b->t_start_s, 12.5);
  RunFilter f;
  auto listed = store->ListRuns(f);
  ASSERT_TRUE(listed.ok());
  ASSERT_EQ(listed->size(), 2u);
  EXPECT_EQ((*listed)[0].key, swept.key);
  // The display name column is there for people reading the file.
  RunRecord bad = MakeRun("x");
  bad.split = "train";
  std::vector<std::int64_t> none;
  auto refused = store->SubmitBatch("alice", "b", "{}", {bad}, &none);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("runs[0].split"), std::string::npos) << refused.status().message();
}

TEST(StoreSchemaTest, Version3FillsRunKeysOfOlderDatabasesFromTheirTags) {
  const std::string path = TempDb("v2_to_v3");
  {
    auto conn = sql::Connection::Open(path);
    ASSERT_TRUE(conn.ok());
    std::vector<schema::Migration> v2(schema::Migrations().begin(), schema::Migrations().begin() + 2);
    auto v = schema::Migrate(&*conn, v2, path);
    ASSERT_TRUE(v.ok()) << v.status().ToString();
    ASSERT_EQ(*v, 2);
  }
  {
    RawDb raw(path);
    raw.Exec("INSERT INTO batches (id, submitter, name, spec_json, created) VALUES (1, 'u', 'b', '{}', 0)");
    const char* insert =
        "INSERT INTO runs (id, batch_id, name, controller, bench_kind, requested_bench, bench_name, spec_json, "
        "submitter, priority, status, requeue_on_interrupt, submitted) VALUES ";
    raw.Exec(Cat(insert, "(1, 1, 'm/pi sweep:conditions.supply_V=24 sweep:x=0.5 repeat:3', 'pi_current', "
                         "'emulated', '', '', '{}', 'u', 0, 'done', 1, 0)"));
    raw.Exec(Cat(insert, "(2, 1, 'r07', 'imported', 'imported', '', '', '{}', 'u', 0, 'done', 0, 0)"));
    raw.Exec(Cat(insert, "(3, 1, 'plain', 'pi_current', 'emulated', '', '', '{}', 'u', 0, 'queued', 1, 0)"));
    raw.Exec("INSERT INTO run_tags (run_id, tag) VALUES (1, 'sweep:conditions.supply_V=24'), (1, 'sweep:x=0.5'), "
             "(1, 'repeat:3'), (2, 'imported'), (2, 'split:fit'), (2, 't_start_s:7.25')");
  }
  auto store = OpenOrDie(path);
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(store->schema_version(), schema::CurrentVersion());
  auto a = store->GetRun(1);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  EXPECT_EQ(a->key, (RunKey{"m/pi", {{"conditions.supply_V", 24.0}, {"x", 0.5}}, 3}));
  auto b = store->GetRun(2);
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->key, NamedRun("r07"));
  EXPECT_EQ(b->split, "fit");
  EXPECT_EQ(b->t_start_s, 7.25);
  auto c = store->GetRun(3);
  ASSERT_TRUE(c.ok());
  EXPECT_EQ(c->key, NamedRun("plain"));
  EXPECT_TRUE(std::isnan(c->t_start_s));
}

// A store written at version 5 (before runs kept what executing them measured) opens at the current version with
// its runs as they were: a finished run has no execution record (nothing is made up), and a run finished after
// the upgrade stores its own.
TEST(StoreSchemaTest, Version6KeepsOlderRunsAndStoresExecutionsFromThenOn) {
  const std::string path = TempDb("v5_to_v6");
  {
    auto conn = sql::Connection::Open(path);
    ASSERT_TRUE(conn.ok());
    std::vector<schema::Migration> v5(schema::Migrations().begin(), schema::Migrations().begin() + 5);
    auto v = schema::Migrate(&*conn, v5, path);
    ASSERT_TRUE(v.ok()) << v.status().ToString();
    ASSERT_EQ(*v, 5);
  }
  {
    RawDb raw(path);
    raw.Exec("INSERT INTO batches (id, submitter, name, spec_json, created) VALUES (1, 'u', 'b', '{}', 0)");
    const char* insert =
        "INSERT INTO runs (id, batch_id, name, controller, bench_kind, requested_bench, bench_name, spec_json, "
        "submitter, priority, status, requeue_on_interrupt, submitted, key_name) VALUES ";
    raw.Exec(Cat(insert, "(1, 1, 'old', 'pi_current', 'emulated', '', 'bench-1', '{}', 'u', 0, 'done', 1, 0, 'old')"));
    raw.Exec(Cat(insert, "(2, 1, 'new', 'pi_current', 'emulated', '', '', '{}', 'u', 0, 'queued', 1, 0, 'new')"));
    raw.Exec("INSERT INTO metrics (run_id, name, value) VALUES (1, 'rmse_A', 0.25)");
  }
  auto store = OpenOrDie(path);
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(store->schema_version(), schema::CurrentVersion());
  auto old = store->GetRun(1);
  ASSERT_TRUE(old.ok()) << old.status().ToString();
  EXPECT_EQ(old->status, RunStatus::kDone);
  EXPECT_EQ(old->key.name, "old");
  EXPECT_FALSE(old->execution.has_value()) << "a run finished before v6 has no execution record";
  EXPECT_EQ((*store->GetMetrics(1))[0].value, 0.25);
  ASSERT_EQ(ClaimId(*store), 2);
  ExecutionRecord e;
  e.wall_s = 0.75;
  e.samples = 10;
  e.loop.emplace();
  e.loop->overruns = 3;
  ASSERT_TRUE(store->Finish(vb::db::testing::CurrentLease(store.get(), 2), RunStatus::kDone, "", {}, e).ok());
  auto fresh = store->GetRun(2);
  ASSERT_TRUE(fresh.ok() && fresh->execution.has_value());
  EXPECT_EQ(fresh->execution->wall_s, 0.75);
  ASSERT_TRUE(fresh->execution->loop.has_value());
  EXPECT_EQ(fresh->execution->loop->overruns, 3);
}

TEST(StoreSchemaTest, AFailingMigrationChangesNothing) {
  const std::string path = TempDb("migrate_fail");
  std::vector<schema::Migration> list(schema::Migrations().begin(), schema::Migrations().end());
  const int next = schema::CurrentVersion() + 1;
  list.push_back({next, "broken", "CREATE TABLE fine (a); THIS IS NOT SQL"});
  {
    auto conn = sql::Connection::Open(path);
    ASSERT_TRUE(conn.ok());
    auto v = schema::Migrate(&*conn, list, path);
    ASSERT_FALSE(v.ok());
    EXPECT_NE(v.status().message().find(Cat("schema migration to version ", next)), std::string::npos) << v.status().message();
  }
  {
    RawDb raw(path);
    EXPECT_EQ(raw.Int("PRAGMA user_version"), 0);  // v1.. were in the same transaction: rolled back too
    EXPECT_EQ(raw.Int("SELECT count(*) FROM sqlite_schema"), 0);
  }
  auto store = OpenOrDie(path);  // the real list still works on it
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(store->schema_version(), schema::CurrentVersion());
}

TEST(StoreSchemaTest, MigrationListWithAGapIsABug) {
  const schema::Migration list[] = {{1, "one", "CREATE TABLE a (x)"}, {3, "three", "CREATE TABLE b (x)"}};
  auto conn = sql::Connection::Open(":memory:");
  ASSERT_TRUE(conn.ok());
  auto v = schema::Migrate(&*conn, list, ":memory:");
  ASSERT_FALSE(v.ok());
  EXPECT_EQ(v.status().code(), StatusCode::kInternal);
}

void ExpectNewerSchemaRefused(const std::string& path, const char* journal_mode) {
  const int kNewer = schema::CurrentVersion() + 1;  // a version this build does not know
  {
    RawDb raw(path);
    raw.Exec(Cat("PRAGMA journal_mode = ", journal_mode));
    raw.Exec(Cat("CREATE TABLE future (a); INSERT INTO future VALUES (1); PRAGMA user_version = ", kNewer));
  }
  ASSERT_FALSE(FileExists(path + "-wal"));  // the last connection closed: checkpointed and removed
  const std::string before = ReadFileBytes(path);
  ASSERT_FALSE(before.empty());
  auto store = OpenSqliteStore(path);
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(store.status().message().find(Cat("schema version ", kNewer)), std::string::npos)
      << store.status().message();
  EXPECT_NE(store.status().message().find(Cat("(", schema::CurrentVersion(), ")")), std::string::npos) << store.status().message();
  EXPECT_EQ(ReadFileBytes(path), before) << "the file was modified";
  RawDb raw(path);
  EXPECT_EQ(raw.Text("PRAGMA journal_mode"), journal_mode);
  EXPECT_EQ(raw.Int("PRAGMA user_version"), kNewer);
}

TEST(StoreSchemaTest, RefusesANewerSchemaWithoutTouchingTheFile) {
  ExpectNewerSchemaRefused(TempDb("newer_delete"), "delete");
  ExpectNewerSchemaRefused(TempDb("newer_wal"), "wal");
}

TEST(StoreSchemaTest, RefusesSomebodyElsesDatabase) {
  const std::string path = TempDb("foreign");
  {
    RawDb raw(path);
    raw.Exec("CREATE TABLE recipes (name TEXT); INSERT INTO recipes VALUES ('soup')");
  }
  const std::string before = ReadFileBytes(path);
  auto store = OpenSqliteStore(path);
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(store.status().message().find("not a valvebench database"), std::string::npos) << store.status().message();
  EXPECT_EQ(ReadFileBytes(path), before);
}

TEST(StoreSchemaTest, NotADatabaseIsDataLoss) {
  const std::string path = TempDb("garbage");
  {
    std::ofstream out(path, std::ios::binary);
    out << std::string(8192, 'x');
  }
  auto store = OpenSqliteStore(path);
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), StatusCode::kDataLoss) << store.status().ToString();
  EXPECT_NE(store.status().message().find(path), std::string::npos);
}

TEST(StoreSchemaTest, UnopenablePathIsUnavailable) {
  auto store = OpenSqliteStore("/nonexistent-dir-for-vb-test/x.db");
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), StatusCode::kUnavailable) << store.status().ToString();
  auto empty = OpenSqliteStore("");
  ASSERT_FALSE(empty.ok());
  EXPECT_EQ(empty.status().code(), StatusCode::kInvalidArgument);
}

// ---- submission ----

TEST_P(StoreSubmitTest, StoresEveryFieldAndAQueuedHistoryRow) {
  Store* store = &this->store();
  RunRecord r = MakeRun("sweep/duty=0.3/rep=1", 7, "emulated", "bench-a", {"nightly", "duty=0.3"});
  r.requeue_on_interrupt = false;
  r.spec_json = "{ \"exact\":  [1, 2.50, \"verbatim\"] }\n";
  std::int64_t batch_id = 0;
  auto ids = Submit(*store, {r}, "alice", &batch_id);
  ASSERT_EQ(ids.size(), 1u);
  auto got = store->GetRun(ids[0]);
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(got->id, ids[0]);
  EXPECT_EQ(got->batch_id, batch_id);
  EXPECT_EQ(got->key, r.key);
  EXPECT_EQ(got->controller, "pi_current");
  EXPECT_EQ(got->bench_kind, "emulated");
  EXPECT_EQ(got->bench_name, "bench-a");
  EXPECT_EQ(got->spec_json, r.spec_json);
  EXPECT_EQ(got->submitter, "alice");
  EXPECT_EQ(got->priority, 7);
  EXPECT_EQ(got->status, RunStatus::kQueued);
  EXPECT_FALSE(got->requeue_on_interrupt);
  EXPECT_EQ(got->tags, (std::vector<std::string>{"nightly", "duty=0.3"}));  // submission order
  const double now = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  EXPECT_NEAR(got->submitted_unix_s, now, 60);
  EXPECT_EQ(got->started_unix_s, 0.0);
  EXPECT_EQ(got->progress, 0.0);
  auto h = store->History(ids[0]);
  ASSERT_TRUE(h.ok());
  ASSERT_EQ(h->size(), 1u);
  EXPECT_EQ((*h)[0].status, RunStatus::kQueued);
  EXPECT_EQ((*h)[0].at_unix_s, got->submitted_unix_s);
}

TEST_P(StoreSubmitTest, BadInputNamesTheFieldAndStoresNothing) {
  Store* store = &this->store();
  struct Case {
    std::string submitter;
    std::vector<RunRecord> runs;
    std::string field;
  };
  RunRecord no_name = MakeRun("");
  RunRecord no_spec = MakeRun("x");
  no_spec.spec_json.clear();
  RunRecord other_user = MakeRun("x");
  other_user.submitter = "mallory";
  const std::vector<Case> cases = {
      {"", {MakeRun("a")}, "submitter: must not be empty"},
      {"alice", {}, "runs: a batch needs at least one run"},
      {"alice", {MakeRun("a"), no_name}, "runs[1].key.name: must not be empty"},
      {"alice", {no_spec}, "runs[0].spec_json"},
      {"alice", {other_user}, "runs[0].submitter"},
      {"alice", {MakeRun("a", 0, "emulated", "", {"x", ""})}, "runs[0].tags[1]: must not be empty"},
      {"alice", {MakeRun("a"), MakeRun("b", 0, "emulated", "", {"x", "x"})}, "runs[1].tags[1]: duplicate tag"},
  };
  for (const Case& c : cases) {
    std::vector<std::int64_t> ids;
    auto b = store->SubmitBatch(c.submitter, "batch", "{}", c.runs, &ids);
    ASSERT_FALSE(b.ok()) << c.field;
    EXPECT_EQ(b.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(b.status().message().find(c.field), std::string::npos) << b.status().message();
  }
  auto all = store->ListRuns(RunFilter{});
  ASSERT_TRUE(all.ok());
  EXPECT_TRUE(all->empty());
  auto n = store->CountQueued("");
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(*n, 0);
}

// Fault injection: a trigger makes SQLite fail half-way through a transaction; nothing of it may remain.
TEST_P(StoreAtomicityTest, AFailureHalfWayRollsTheWholeMethodBack) {
  Store* store = &this->store();
  auto first = Submit(*store, {MakeRun("before")});
  ASSERT_EQ(ClaimId(*store), first[0]);
  if (postgres()) {
    RawExec("CREATE FUNCTION boom() RETURNS trigger LANGUAGE plpgsql AS $$ BEGIN RAISE EXCEPTION 'injected fault'; "
            "END $$;"
            "CREATE TRIGGER boom_run BEFORE INSERT ON runs FOR EACH ROW WHEN (NEW.name = 'boom') "
            "EXECUTE FUNCTION boom();"
            "CREATE TRIGGER boom_metric BEFORE INSERT ON metrics FOR EACH ROW WHEN (NEW.name = 'boom') "
            "EXECUTE FUNCTION boom();"
            "CREATE TRIGGER boom_chunk BEFORE INSERT ON trace_chunks FOR EACH ROW WHEN (NEW.idx = 1) "
            "EXECUTE FUNCTION boom();");
  } else {
    RawExec("CREATE TRIGGER boom_run BEFORE INSERT ON runs WHEN NEW.name = 'boom' "
             "BEGIN SELECT RAISE(ABORT, 'injected fault'); END;"
             "CREATE TRIGGER boom_metric BEFORE INSERT ON metrics WHEN NEW.name = 'boom' "
             "BEGIN SELECT RAISE(ABORT, 'injected fault'); END;"
             "CREATE TRIGGER boom_chunk BEFORE INSERT ON trace_chunks WHEN NEW.idx = 1 "
             "BEGIN SELECT RAISE(ABORT, 'injected fault'); END;");
  }
  // The third run fails after the batch row, two runs, their tags and history rows were written.
  std::vector<std::int64_t> ids;
  auto b = store->SubmitBatch("alice", "b", "{}", {MakeRun("a", 0, "emulated", "", {"t"}), MakeRun("b"),
                                                   MakeRun("boom")}, &ids);
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.status().message().find("injected fault"), std::string::npos) << b.status().message();
  EXPECT_TRUE(ids.empty());
  // Metrics are written after the status change and the history row.
  Status f = store->Finish(vb::db::testing::CurrentLease(store, first[0]), RunStatus::kDone, "", {{"rmse_A", 1}, {"boom", 2}});
  ASSERT_FALSE(f.ok());
  // The second chunk fails; the first stays.
  ASSERT_TRUE(store->AppendTraceChunk(vb::db::testing::CurrentLease(store, first[0]), MakeChunk(0, 10, {"i_A"}, 1)).ok());
  EXPECT_FALSE(store->AppendTraceChunk(vb::db::testing::CurrentLease(store, first[0]), MakeChunk(1, 10, {"i_A"}, 2)).ok());

  EXPECT_EQ(RawInt("SELECT count(*) FROM batches"), 1);
  EXPECT_EQ(RawInt("SELECT count(*) FROM runs"), 1);
  EXPECT_EQ(RawInt("SELECT count(*) FROM run_tags"), 0);
  EXPECT_EQ(RawInt("SELECT count(*) FROM status_history"), 2);  // queued + running of the first run
  EXPECT_EQ(RawInt("SELECT count(*) FROM metrics"), 0);
  EXPECT_EQ(RawInt("SELECT count(*) FROM trace_chunks"), 1);
  EXPECT_EQ(store->GetRun(first[0])->status, RunStatus::kRunning);
  // And the Store is still usable: no transaction was left open.
  EXPECT_TRUE(store->Finish(vb::db::testing::CurrentLease(store, first[0]), RunStatus::kDone, "", {{"rmse_A", 1}}).ok());
  EXPECT_EQ(Submit(*store, {MakeRun("after")}).size(), 1u);
}

TEST_P(StoreSubmitTest, UnknownRunIsNotFoundEverywhere) {
  Store* store = &this->store();
  auto run = store->GetRun(42);
  ASSERT_FALSE(run.ok());
  EXPECT_EQ(run.status().code(), StatusCode::kNotFound);
  EXPECT_EQ(run.status().message(), "run 42 not found");
  EXPECT_EQ(store->History(42).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store->GetMetrics(42).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store->ReadTrace(42).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store->SetProgress(vb::db::testing::CurrentLease(store, 42), 0.5).code(), StatusCode::kNotFound);
  EXPECT_EQ(store->Finish(vb::db::testing::CurrentLease(store, 42), RunStatus::kDone, "", {}).code(), StatusCode::kNotFound);
  EXPECT_EQ(store->RequestCancel(42, "why").status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store->CancelRequested(42).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store->AppendTraceChunk(vb::db::testing::CurrentLease(store, 42), MakeChunk(0, 4, {"i_A"}, 1)).code(), StatusCode::kNotFound);
}

// ---- the queue ----

TEST_P(StoreQueueTest, ClaimsByPriorityThenAge) {
  Store* store = &this->store();
  auto first = Submit(*store, {MakeRun("p0-a", 0), MakeRun("p5-a", 5), MakeRun("p0-b", 0)});
  auto second = Submit(*store, {MakeRun("p5-b", 5), MakeRun("p10", 10), MakeRun("p-3", -3)}, "bob");
  const std::vector<std::int64_t> expected = {second[1], first[1], second[0], first[0], first[2], second[2]};
  std::vector<std::int64_t> claimed;
  for (std::size_t k = 0; k < expected.size(); ++k) {
    auto c = store->ClaimNext(db::BenchClaim("emulated", "bench-1"));
    ASSERT_TRUE(c.ok()) << c.status().ToString();
    ASSERT_TRUE(c->has_value());
    EXPECT_EQ((*c)->status, RunStatus::kRunning);
    EXPECT_EQ((*c)->bench_name, "bench-1");
    EXPECT_GT((*c)->started_unix_s, 0.0);
    claimed.push_back((*c)->id);
  }
  EXPECT_EQ(claimed, expected);
  auto none = store->ClaimNext(db::BenchClaim("emulated", "bench-1"));
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->has_value());
}

TEST_P(StoreQueueTest, ClaimMatchesBenchKindAndName) {
  Store* store = &this->store();
  auto ids = Submit(*store, {MakeRun("emu-any", 0, "emulated", ""), MakeRun("usb-any", 0, "usb", ""),
                             MakeRun("any-kind", 0, "", ""), MakeRun("emu-on-b", 9, "emulated", "bench-b")});
  // bench-a (emulated) cannot take the run that asked for bench-b, even though it has the top priority.
  auto a = store->ClaimNext(db::BenchClaim("emulated", "bench-a"));
  ASSERT_TRUE(a.ok());
  ASSERT_TRUE(a->has_value());
  EXPECT_EQ((*a)->id, ids[0]);
  EXPECT_EQ((*a)->bench_name, "bench-a");
  // A USB bench takes the USB run, then the run of any kind, then nothing (the rest are emulated).
  EXPECT_EQ(ClaimId(*store, "usb", "usb-1"), ids[1]);
  EXPECT_EQ(ClaimId(*store, "usb", "usb-1"), ids[2]);
  EXPECT_EQ(ClaimId(*store, "usb", "usb-1"), 0);
  EXPECT_EQ(ClaimId(*store, "emulated", "bench-a"), 0);
  EXPECT_EQ(ClaimId(*store, "emulated", "bench-b"), ids[3]);
  auto bad = store->ClaimNext(db::BenchClaim("emulated", ""));
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find("bench_name"), std::string::npos);
}

TEST_P(StoreQueueTest, TwoConnectionsInTwoThreadsClaimEveryRunExactlyOnce) {
  constexpr int kThreads = 2;
  constexpr int kRunsPerThread = 200;
  {
    Store* store = &this->store();
    std::vector<RunRecord> runs;
    for (int k = 0; k < kThreads * kRunsPerThread; ++k) runs.push_back(MakeRun(Cat("r", k), k % 3));
    ASSERT_EQ(Submit(*store, std::move(runs)).size(), static_cast<std::size_t>(kThreads * kRunsPerThread));
  }
  std::vector<std::vector<std::int64_t>> claimed(kThreads);
  std::vector<std::string> errors(kThreads);
  std::atomic<int> ready{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      auto opened = OpenStore(location());  // one Store (connection) per thread
      if (!opened.ok()) {
        errors[t] = opened.status().ToString();
        return;
      }
      auto& store = *opened;
      ready.fetch_add(1);
      while (ready.load() < kThreads) std::this_thread::yield();
      const std::string bench = Cat("bench-", t);
      while (true) {
        auto c = store->ClaimNext(db::BenchClaim("emulated", bench));
        if (!c.ok()) {
          errors[t] = c.status().ToString();
          return;
        }
        if (!c->has_value()) return;
        claimed[t].push_back((*c)->id);
        // Finishing in between makes the two writers contend for the lock the way workers do.
        Status f = store->Finish(db::LeaseOf(**c), RunStatus::kDone, "", {{"claimed_by", static_cast<double>(t)}});
        if (!f.ok()) {
          errors[t] = f.ToString();
          return;
        }
      }
    });
  }
  for (auto& th : threads) th.join();
  for (int t = 0; t < kThreads; ++t) EXPECT_EQ(errors[t], "") << "thread " << t;
  std::multiset<std::int64_t> all;
  for (const auto& c : claimed) all.insert(c.begin(), c.end());
  std::set<std::int64_t> unique(all.begin(), all.end());
  EXPECT_EQ(all.size(), static_cast<std::size_t>(kThreads * kRunsPerThread));
  EXPECT_EQ(unique.size(), all.size()) << "some run was claimed twice";
  EXPECT_EQ(RawInt("SELECT count(*) FROM runs WHERE status = 'done'"), kThreads * kRunsPerThread);
  EXPECT_EQ(RawInt("SELECT count(*) FROM status_history WHERE status = 'running'"), kThreads * kRunsPerThread);
  EXPECT_EQ(RawInt("SELECT max(n) FROM (SELECT count(*) AS n FROM status_history WHERE status = 'running' "
                   "GROUP BY run_id) AS per_run"),
            1);
  // Each thread finished exactly the runs it claimed.
  for (int t = 0; t < kThreads; ++t) {
    EXPECT_EQ(RawInt(Cat("SELECT count(*) FROM runs WHERE bench_name = 'bench-", t, "'")),
              static_cast<std::int64_t>(claimed[t].size()));
  }
}

TEST_P(StoreQueueTest, CountQueuedPerSubmitter) {
  Store* store = &this->store();
  Submit(*store, {MakeRun("a"), MakeRun("b")}, "alice");
  Submit(*store, {MakeRun("c")}, "bob");
  ClaimId(*store);  // takes one of alice's
  EXPECT_EQ(*store->CountQueued("alice"), 1);
  EXPECT_EQ(*store->CountQueued("bob"), 1);
  EXPECT_EQ(*store->CountQueued("carol"), 0);
  EXPECT_EQ(*store->CountQueued(""), 2);
}

// ---- progress, finish, cancel, history ----

TEST_P(StoreRunTest, FinishWithMetricsAndHistory) {
  Store* store = &this->store();
  auto ids = Submit(*store, {MakeRun("a")});
  ASSERT_EQ(ClaimId(*store), ids[0]);
  ASSERT_TRUE(store->SetProgress(vb::db::testing::CurrentLease(store, ids[0]), 0.25).ok());
  EXPECT_EQ(store->GetRun(ids[0])->progress, 0.25);
  EXPECT_EQ(store->SetProgress(vb::db::testing::CurrentLease(store, ids[0]), 1.5).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store->SetProgress(vb::db::testing::CurrentLease(store, ids[0]), std::nan("")).code(), StatusCode::kInvalidArgument);

  const std::vector<Metric> metrics = {{"rmse_A", 0.0125}, {"effort_J", 3.5}, {"overshoot", std::nan("")},
                                       {"settle_s", std::numeric_limits<double>::infinity()}};
  // Bad metrics change nothing.
  Status dup = store->Finish(vb::db::testing::CurrentLease(store, ids[0]), RunStatus::kDone, "", {{"a", 1}, {"a", 2}});
  EXPECT_EQ(dup.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(dup.message().find("metrics[1].name: duplicate metric \"a\""), std::string::npos) << dup.message();
  EXPECT_EQ(store->Finish(vb::db::testing::CurrentLease(store, ids[0]), RunStatus::kDone, "", {{"", 1}}).code(), StatusCode::kInvalidArgument);
  Status not_final = store->Finish(vb::db::testing::CurrentLease(store, ids[0]), RunStatus::kQueued, "", {});
  EXPECT_EQ(not_final.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(not_final.message().find("final_status"), std::string::npos);
  EXPECT_EQ(store->GetRun(ids[0])->status, RunStatus::kRunning);

  ASSERT_TRUE(store->Finish(vb::db::testing::CurrentLease(store, ids[0]), RunStatus::kDone, "", metrics).ok());
  auto run = store->GetRun(ids[0]);
  ASSERT_TRUE(run.ok());
  EXPECT_EQ(run->status, RunStatus::kDone);
  EXPECT_EQ(run->progress, 1.0);
  EXPECT_GE(run->finished_unix_s, run->started_unix_s);
  EXPECT_GE(run->started_unix_s, run->submitted_unix_s);

  auto got = store->GetMetrics(ids[0]);
  ASSERT_TRUE(got.ok());
  ASSERT_EQ(got->size(), 4u);  // sorted by name
  EXPECT_EQ((*got)[0].name, "effort_J");
  EXPECT_EQ((*got)[0].value, 3.5);
  EXPECT_EQ((*got)[1].name, "overshoot");
  EXPECT_TRUE(std::isnan((*got)[1].value));
  EXPECT_EQ((*got)[2].name, "rmse_A");
  EXPECT_EQ((*got)[2].value, 0.0125);
  EXPECT_EQ((*got)[3].name, "settle_s");
  EXPECT_EQ((*got)[3].value, std::numeric_limits<double>::infinity());

  auto h = store->History(ids[0]);
  ASSERT_TRUE(h.ok());
  ASSERT_EQ(h->size(), 3u);
  EXPECT_EQ((*h)[0].status, RunStatus::kQueued);
  EXPECT_EQ((*h)[1].status, RunStatus::kRunning);
  EXPECT_EQ((*h)[2].status, RunStatus::kDone);
  EXPECT_LE((*h)[0].at_unix_s, (*h)[1].at_unix_s);
  EXPECT_LE((*h)[1].at_unix_s, (*h)[2].at_unix_s);
  EXPECT_EQ((*h)[2].at_unix_s, run->finished_unix_s);

  // A finished run cannot finish again, report progress or be cancelled.
  Status again = store->Finish(vb::db::testing::CurrentLease(store, ids[0]), RunStatus::kFailed, "x", {});
  EXPECT_EQ(again.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(again.message().find("is done, not running"), std::string::npos) << again.message();
  EXPECT_EQ(store->SetProgress(vb::db::testing::CurrentLease(store, ids[0]), 0.5).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store->RequestCancel(ids[0], "late").status().code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store->GetMetrics(ids[0])->size(), 4u);
}

// What executing a run measured is written by the Finish that ends it and read back with the run, on both
// engines and through another connection (a reopened store): a paced run's loop statistics, a run not paced
// without them (absent, not zeros), a run that never executed without any; the build that executed it, or none
// ("" stored as NULL). Bad numbers and builds name the field and change nothing.
TEST_P(StoreRunTest, ExecutionAndLoopStatisticsAreStoredWithTheRun) {
  Store* store = &this->store();
  auto ids = Submit(*store, {MakeRun("paced"), MakeRun("unpaced"), MakeRun("never")});
  ExecutionRecord paced;
  paced.wall_s = 1.25;
  paced.simulated_s = 1.0;
  paced.samples = 50001;
  paced.control_ticks = 20001;
  paced.metrics_from_trajectory = true;
  paced.loop.emplace();
  paced.loop->ticks = 20001;
  paced.loop->overruns = 17;
  paced.loop->jitter_p50_s = 12.5e-6;
  paced.loop->jitter_p99_s = 81.25e-6;
  paced.loop->jitter_max_s = 1.5e-3;
  paced.build = "valvebench 0.1.0 sha256:00112233445566778899aabbccddeeff";
  ExecutionRecord unpaced = paced;
  unpaced.loop.reset();
  unpaced.wall_s = 0.01;
  unpaced.build = "";

  ASSERT_EQ(ClaimId(*store), ids[0]);
  ExecutionRecord bad = paced;
  bad.wall_s = -1.0;
  Status refused = store->Finish(vb::db::testing::CurrentLease(store, ids[0]), RunStatus::kDone, "", {}, bad);
  EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.message().find("execution.wall_s"), std::string::npos) << refused.message();
  EXPECT_EQ(store->GetRun(ids[0])->status, RunStatus::kRunning);
  bad = paced;
  bad.build = "valvebench\n0.1.0";
  refused = store->Finish(vb::db::testing::CurrentLease(store, ids[0]), RunStatus::kDone, "", {}, bad);
  EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.message().find("execution.build"), std::string::npos) << refused.message();
  bad.build = std::string(201, 'x');
  refused = store->Finish(vb::db::testing::CurrentLease(store, ids[0]), RunStatus::kDone, "", {}, bad);
  EXPECT_NE(refused.message().find("execution.build: at most 200"), std::string::npos) << refused.message();
  EXPECT_EQ(store->GetRun(ids[0])->status, RunStatus::kRunning);
  ASSERT_TRUE(store->Finish(vb::db::testing::CurrentLease(store, ids[0]), RunStatus::kDone, "", {{"rmse_A", 0.5}},
                            paced).ok());
  ASSERT_EQ(ClaimId(*store), ids[1]);
  ASSERT_TRUE(store->Finish(vb::db::testing::CurrentLease(store, ids[1]), RunStatus::kCancelled, "stop", {},
                            unpaced).ok());
  ASSERT_EQ(ClaimId(*store), ids[2]);
  ASSERT_TRUE(store->Finish(vb::db::testing::CurrentLease(store, ids[2]), RunStatus::kFailed, "bad spec", {}).ok());

  auto check = [&](Store& s, const char* where) {
    SCOPED_TRACE(where);
    auto a = s.GetRun(ids[0]);
    ASSERT_TRUE(a.ok()) << a.status().ToString();
    ASSERT_TRUE(a->execution.has_value());
    EXPECT_EQ(a->execution->wall_s, 1.25);
    EXPECT_EQ(a->execution->simulated_s, 1.0);
    EXPECT_EQ(a->execution->samples, 50001);
    EXPECT_EQ(a->execution->control_ticks, 20001);
    EXPECT_TRUE(a->execution->metrics_from_trajectory);
    ASSERT_TRUE(a->execution->loop.has_value());
    EXPECT_EQ(a->execution->loop->ticks, 20001);
    EXPECT_EQ(a->execution->loop->overruns, 17);
    EXPECT_EQ(a->execution->loop->jitter_p50_s, 12.5e-6);  // exact: stored as doubles
    EXPECT_EQ(a->execution->loop->jitter_p99_s, 81.25e-6);
    EXPECT_EQ(a->execution->loop->jitter_max_s, 1.5e-3);
    EXPECT_EQ(a->execution->build, "valvebench 0.1.0 sha256:00112233445566778899aabbccddeeff");
    auto b = s.GetRun(ids[1]);
    ASSERT_TRUE(b.ok() && b->execution.has_value());
    EXPECT_EQ(b->execution->wall_s, 0.01);
    EXPECT_EQ(b->execution->build, "") << "no build known: stored as NULL, read back as none";
    EXPECT_FALSE(b->execution->loop.has_value()) << "a loop that was not paced has no statistics";
    auto c = s.GetRun(ids[2]);
    ASSERT_TRUE(c.ok());
    EXPECT_FALSE(c->execution.has_value());
    auto listed = s.ListRuns(RunFilter{});  // listings carry it too
    ASSERT_TRUE(listed.ok());
    ASSERT_EQ(listed->size(), 3u);
    for (const auto& r : *listed)
      if (r.id == ids[0]) {
        ASSERT_TRUE(r.execution && r.execution->loop);
        EXPECT_EQ(r.execution->loop->overruns, 17);
      }
  };
  check(*store, "the writing connection");
  auto again = OpenAnother();
  ASSERT_NE(again, nullptr);
  check(*again, "the store reopened");
}

TEST_P(StoreRunTest, FinishOfAQueuedRunIsAPreconditionFailure) {
  Store* store = &this->store();
  auto ids = Submit(*store, {MakeRun("a")});
  EXPECT_EQ(store->Finish(vb::db::testing::CurrentLease(store, ids[0]), RunStatus::kFailed, "no", {}).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store->SetProgress(vb::db::testing::CurrentLease(store, ids[0]), 0.5).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store->GetRun(ids[0])->status, RunStatus::kQueued);
}

TEST_P(StoreRunTest, FailedRunKeepsItsReason) {
  Store* store = &this->store();
  auto ids = Submit(*store, {MakeRun("a")});
  ClaimId(*store);
  ASSERT_TRUE(store->Finish(vb::db::testing::CurrentLease(store, ids[0]), RunStatus::kFailed, "safety trip: current_A > 3", {}).ok());
  auto run = store->GetRun(ids[0]);
  EXPECT_EQ(run->status, RunStatus::kFailed);
  EXPECT_EQ(run->reason, "safety trip: current_A > 3");
  EXPECT_EQ(store->History(ids[0])->back().reason, "safety trip: current_A > 3");
}

TEST_P(StoreRunTest, CancelQueuedAtOnceAndRunningOnRequest) {
  Store* store = &this->store();
  auto ids = Submit(*store, {MakeRun("running", 1), MakeRun("queued", 0)});
  ASSERT_EQ(ClaimId(*store), ids[0]);

  auto q = store->RequestCancel(ids[1], "not needed");
  ASSERT_TRUE(q.ok()) << q.status().ToString();
  EXPECT_EQ(*q, RunStatus::kCancelled);
  auto queued = store->GetRun(ids[1]);
  EXPECT_EQ(queued->status, RunStatus::kCancelled);
  EXPECT_EQ(queued->reason, "not needed");
  EXPECT_GT(queued->finished_unix_s, 0.0);
  EXPECT_EQ(HistoryStatuses(*store, ids[1]), (std::vector<RunStatus>{RunStatus::kQueued, RunStatus::kCancelled}));
  EXPECT_EQ(ClaimId(*store), 0) << "a cancelled run must not be claimed";
  auto twice = store->RequestCancel(ids[1], "again");
  EXPECT_EQ(twice.status().code(), StatusCode::kFailedPrecondition);

  EXPECT_FALSE(*store->CancelRequested(ids[0]));
  auto r = store->RequestCancel(ids[0], "user asked");
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(*r, RunStatus::kRunning);
  EXPECT_TRUE(*store->CancelRequested(ids[0]));
  EXPECT_EQ(store->GetRun(ids[0])->status, RunStatus::kRunning);
  EXPECT_EQ(*store->RequestCancel(ids[0], "user asked"), RunStatus::kRunning);  // idempotent
  ASSERT_TRUE(store->Finish(vb::db::testing::CurrentLease(store, ids[0]), RunStatus::kCancelled, "user asked", {}).ok());
  EXPECT_EQ(HistoryStatuses(*store, ids[0]),
            (std::vector<RunStatus>{RunStatus::kQueued, RunStatus::kRunning, RunStatus::kCancelled}));
}

// ---- crash recovery ----

TEST_P(StoreRecoveryTest, RecoverAfterCrashRequeuesOrInterrupts) {
  std::vector<std::int64_t> ids;
  {
    auto store = OpenAnother();
    RunRecord keep = MakeRun("requeue-me", 5, "emulated", "");
    RunRecord once = MakeRun("run-once", 4);
    once.requeue_on_interrupt = false;
    RunRecord cancel = MakeRun("cancel-me", 3);
    RunRecord done = MakeRun("done", 2);
    RunRecord waiting = MakeRun("waiting", 1);
    ids = Submit(*store, {keep, once, cancel, done, waiting});
    for (int k = 0; k < 4; ++k) ASSERT_EQ(ClaimId(*store, "emulated", "bench-x"), ids[k]);
    ASSERT_TRUE(store->AppendTraceChunk(vb::db::testing::CurrentLease(store, ids[0]), MakeChunk(0, 8, {"i_A"}, 3)).ok());
    ASSERT_TRUE(store->SetProgress(vb::db::testing::CurrentLease(store, ids[0]), 0.6).ok());
    ASSERT_EQ(*store->RequestCancel(ids[2], "user asked"), RunStatus::kRunning);
    ASSERT_TRUE(store->Finish(vb::db::testing::CurrentLease(store, ids[3]), RunStatus::kDone, "", {}).ok());
    // The "server" dies here: the Store goes away without Finish for ids[0..2].
  }
  auto store = OpenAnother();
  auto n = store->RecoverAfterCrash("");
  ASSERT_TRUE(n.ok()) << n.status().ToString();
  EXPECT_EQ(*n, 3);

  auto keep = store->GetRun(ids[0]);
  EXPECT_EQ(keep->status, RunStatus::kQueued);
  EXPECT_EQ(keep->priority, 5);
  EXPECT_EQ(keep->bench_name, "") << "back to the bench it asked for, not the one it ran on";
  EXPECT_EQ(keep->reason, "server restarted while running");
  EXPECT_EQ(keep->progress, 0.0);
  EXPECT_TRUE(store->ReadTrace(ids[0])->empty()) << "the partial trace of the interrupted attempt is dropped";
  EXPECT_EQ(HistoryStatuses(*store, ids[0]), (std::vector<RunStatus>{RunStatus::kQueued, RunStatus::kRunning,
                                                                     RunStatus::kInterrupted, RunStatus::kQueued}));
  EXPECT_EQ(store->History(ids[0])->at(2).reason, "server restarted while running");

  auto once = store->GetRun(ids[1]);
  EXPECT_EQ(once->status, RunStatus::kInterrupted);
  EXPECT_EQ(once->reason, "server restarted while running");
  EXPECT_EQ(HistoryStatuses(*store, ids[1]),
            (std::vector<RunStatus>{RunStatus::kQueued, RunStatus::kRunning, RunStatus::kInterrupted}));

  auto cancelled = store->GetRun(ids[2]);
  EXPECT_EQ(cancelled->status, RunStatus::kCancelled);
  EXPECT_EQ(cancelled->reason, "user asked");
  EXPECT_EQ(HistoryStatuses(*store, ids[2]),
            (std::vector<RunStatus>{RunStatus::kQueued, RunStatus::kRunning, RunStatus::kInterrupted,
                                    RunStatus::kCancelled}));
  EXPECT_EQ(store->GetRun(ids[3])->status, RunStatus::kDone);
  EXPECT_EQ(HistoryStatuses(*store, ids[4]), (std::vector<RunStatus>{RunStatus::kQueued}));

  // The requeued run keeps its place: priority 5 beats the waiting priority-1 run; its trace starts afresh.
  auto again = store->ClaimNext(db::BenchClaim("emulated", "bench-y"));
  ASSERT_TRUE(again.ok());
  ASSERT_TRUE(again->has_value());
  EXPECT_EQ((*again)->id, ids[0]);
  EXPECT_EQ((*again)->reason, "");
  EXPECT_TRUE(store->AppendTraceChunk(vb::db::testing::CurrentLease(store, ids[0]), MakeChunk(0, 8, {"i_A"}, 4)).ok());
  EXPECT_EQ(*store->RecoverAfterCrash(""), 1);
  EXPECT_EQ(*store->RecoverAfterCrash(""), 0);
}

// A run that takes the server down at every attempt is re-queued twice, then failed with the reason.
TEST_P(StoreRecoveryTest, APoisonRunIsFailedAtItsThirdInterruption) {
  std::int64_t id = 0;
  {
    auto store = OpenAnother();
    id = Submit(*store, {MakeRun("poison", 1)})[0];
  }
  for (int attempt = 1; attempt <= 3; ++attempt) {
    auto store = OpenAnother();
    ASSERT_EQ(ClaimId(*store, "emulated", "bench-x"), id) << attempt;
    // ... and the "server" dies while it runs.
    auto reopened = OpenAnother();
    ASSERT_EQ(*reopened->RecoverAfterCrash(""), 1);
    const auto run = reopened->GetRun(id);
    if (attempt < 3) {
      EXPECT_EQ(run->status, RunStatus::kQueued) << attempt;
    } else {
      EXPECT_EQ(run->status, RunStatus::kFailed);
      EXPECT_NE(run->reason.find("stopped 3 times while this run ran"), std::string::npos) << run->reason;
      EXPECT_EQ(*reopened->RecoverAfterCrash(""), 0) << "a clean start after it";
    }
  }
}

// Runs `child` in a forked process (it must end with _exit) and returns its pid.
template <typename F>
pid_t Fork(F child) {
  const pid_t pid = fork();
  if (pid == 0) {
    child();
    _exit(0);
  }
  return pid;
}

bool ReadAll(int fd, void* buf, std::size_t n) {
  auto* p = static_cast<char*>(buf);
  while (n > 0) {
    const ssize_t got = read(fd, p, n);
    if (got <= 0) return false;
    p += got;
    n -= static_cast<std::size_t>(got);
  }
  return true;
}

TEST(StoreCrashTest, ProcessExitingWithoutCleanupLosesNothingCommitted) {
  const std::string path = TempDb("crash_exit");
  { ASSERT_NE(OpenOrDie(path), nullptr); }  // create the schema first
  constexpr int kRuns = 20;
  const pid_t pid = Fork([&] {
    auto opened = OpenSqliteStore(path);
    if (!opened.ok()) _exit(10);
    for (int k = 0; k < kRuns; ++k) {
      std::vector<std::int64_t> ids;
      if (!(*opened)->SubmitBatch("child", "b", "{}", {MakeRun(Cat("r", k))}, &ids).ok()) _exit(11);
    }
    auto c = (*opened)->ClaimNext(db::BenchClaim("emulated", "bench-1"));
    if (!c.ok() || !c->has_value()) _exit(12);
    if (!(*opened)->AppendTraceChunk(db::LeaseOf(**c), MakeChunk(0, 100, {"i_A", "x_m"}, 9)).ok()) _exit(13);
    _exit(0);  // no destructors: the connection is never closed, the WAL never checkpointed
  });
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  ASSERT_EQ(WEXITSTATUS(status), 0);

  auto store = OpenOrDie(path);
  auto runs = store->ListRuns(RunFilter{});
  ASSERT_TRUE(runs.ok());
  ASSERT_EQ(runs->size(), static_cast<std::size_t>(kRuns));
  EXPECT_EQ((*runs)[0].status, RunStatus::kRunning);
  for (int k = 1; k < kRuns; ++k) EXPECT_EQ((*runs)[k].status, RunStatus::kQueued);
  auto trace = store->ReadTrace((*runs)[0].id);
  ASSERT_TRUE(trace.ok());
  ASSERT_EQ(trace->size(), 1u);
  EXPECT_EQ((*trace)[0].data, MakeChunk(0, 100, {"i_A", "x_m"}, 9).data);
  EXPECT_EQ(*store->RecoverAfterCrash(""), 1);
  EXPECT_EQ(*store->CountQueued(""), kRuns);
}

TEST(StoreCrashTest, SigkilledWriterLosesNothingCommitted) {
  const std::string path = TempDb("crash_kill");
  { ASSERT_NE(OpenOrDie(path), nullptr); }
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  // The child submits one-run batches as fast as it can, reporting each id after its commit returned; the
  // fifth run it claims right away (reported as -id). It never stops by itself: the parent SIGKILLs it mid-write.
  const pid_t pid = Fork([&] {
    close(fds[0]);
    auto opened = OpenSqliteStore(path);
    if (!opened.ok()) _exit(10);
    Store& store = **opened;
    for (int k = 0;; ++k) {
      std::vector<std::int64_t> ids;
      RunRecord r = MakeRun(Cat("r", k), 0, "emulated", "", {Cat("t", k % 3)});
      // The second run is for a bench of its own kind, so claiming it (a trace is written only by the attempt
      // that holds the run) never takes a first run.
      if (!store.SubmitBatch("child", "b", "{}", {r, MakeRun("second", 0, "tracer", "", {"t"})}, &ids).ok()) _exit(11);
      if (write(fds[1], &ids[0], sizeof ids[0]) != sizeof ids[0]) _exit(12);
      if (k == 4) {
        auto c = store.ClaimNext(db::BenchClaim("emulated", "bench-1"));
        if (!c.ok() || !c->has_value()) _exit(13);
        const std::int64_t claimed = -(*c)->id;
        if (write(fds[1], &claimed, sizeof claimed) != sizeof claimed) _exit(14);
      }
      // Traces too, so the kill may land in the middle of a large write.
      auto second = store.ClaimNext(db::BenchClaim("tracer", "tracer-1"));
      if (!second.ok() || !second->has_value() || (*second)->id != ids[1]) _exit(16);
      if (!store.AppendTraceChunk(db::LeaseOf(**second), MakeChunk(0, 2000, {"a", "b", "c"}, 7)).ok()) _exit(15);
    }
  });
  close(fds[1]);
  std::vector<std::int64_t> reported;
  std::int64_t claimed = 0;
  std::int64_t v = 0;
  while (reported.size() < 60 && ReadAll(fds[0], &v, sizeof v)) {
    if (v < 0) {
      claimed = -v;
    } else {
      reported.push_back(v);
    }
  }
  ASSERT_EQ(kill(pid, SIGKILL), 0);
  while (ReadAll(fds[0], &v, sizeof v)) {  // whatever was committed and reported before the kill
    if (v < 0) {
      claimed = -v;
    } else {
      reported.push_back(v);
    }
  }
  close(fds[0]);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFSIGNALED(status)) << "child exited with " << WEXITSTATUS(status);
  ASSERT_GE(reported.size(), 60u);
  ASSERT_NE(claimed, 0);

  {
    RawDb raw(path);
    EXPECT_EQ(raw.Text("PRAGMA integrity_check"), "ok");
    EXPECT_EQ(raw.Int("SELECT count(*) FROM pragma_foreign_key_check"), 0);
  }
  auto store = OpenOrDie(path);
  for (std::int64_t id : reported) {
    auto run = store->GetRun(id);
    ASSERT_TRUE(run.ok()) << "run " << id << " was reported committed but is gone: " << run.status().ToString();
    EXPECT_EQ(run->status, id == claimed ? RunStatus::kRunning : RunStatus::kQueued) << id;
    // Claimed for its trace right after the batch was reported (the kill may land in between for the last).
    if (id != reported.back()) {
      EXPECT_EQ(store->GetRun(id + 1)->status, RunStatus::kRunning) << id + 1;
    }
    EXPECT_EQ(run->tags.size(), 1u);
  }
  // Every batch is whole (two runs) and every stored trace chunk is intact: no half transaction survived.
  RawDb raw(path);
  EXPECT_EQ(raw.Int("SELECT count(*) FROM (SELECT batch_id FROM runs GROUP BY batch_id HAVING count(*) != 2)"), 0);
  EXPECT_EQ(raw.Int("SELECT count(*) FROM trace_chunks WHERE samples != 2000"), 0);
  const std::vector<double> written = MakeChunk(0, 2000, {"a", "b", "c"}, 7).data;
  for (std::int64_t id : reported) {
    auto trace = store->ReadTrace(id + 1);  // each batch's second run carries the trace
    ASSERT_TRUE(trace.ok()) << trace.status().ToString();
    for (const TraceChunk& c : *trace) EXPECT_EQ(c.data, written) << "run " << id + 1;
  }
  const std::int64_t running = raw.Int("SELECT count(*) FROM runs WHERE status = 'running'");
  EXPECT_GE(running, static_cast<std::int64_t>(reported.size()));
  EXPECT_EQ(*store->RecoverAfterCrash(""), running);
}

// ---- background checkpoints ----

TEST(CheckpointerTest, CheckpointsOffTheCommittingThreadAndBoundsTheWal) {
  const std::string path = TempDb("checkpointer");
  { ASSERT_NE(OpenOrDie(path), nullptr); }  // a store file: WAL mode, 32 KiB pages
  RawDb raw(path);
  raw.Exec("CREATE TABLE scratch (b BLOB)");
  Checkpointer::Options options;
  options.request_every_pages = 8;
  options.wait_above_pages = 32;
  auto checkpointer = Checkpointer::Start(path, options);
  ASSERT_NE(checkpointer, nullptr);
  checkpointer->Attach(raw.db);
  // ~3 pages per commit, ~900 pages in all: without the hook SQLite would let the WAL reach 1000 pages.
  for (int k = 0; k < 300; ++k) raw.Exec("INSERT INTO scratch VALUES (zeroblob(65536))");
  Checkpointer::Detach(raw.db);
  EXPECT_GT(checkpointer->passes(), 0u);
  struct stat wal;
  ASSERT_EQ(stat((path + "-wal").c_str(), &wal), 0);
  const long frame_bytes = 32768 + 24;
  EXPECT_LT(wal.st_size, 48 * frame_bytes) << "the WAL outgrew the back-pressure bound: " << wal.st_size / frame_bytes
                                            << " frames";
  EXPECT_EQ(raw.Int("SELECT count(*) FROM scratch"), 300);
  EXPECT_EQ(raw.Text("PRAGMA integrity_check"), "ok");
}

TEST(CheckpointerTest, NoCheckpointerForInMemoryDatabases) {
  EXPECT_EQ(Checkpointer::Start("", Checkpointer::Options{}), nullptr);
}

// ---- listing ----

class StoreListTest : public testing::StoreEngineTest {
 protected:
  void SetUp() override {
    StoreEngineTest::SetUp();
    if (IsSkipped() || HasFatalFailure()) return;
    RunRecord a1 = MakeRun("a1", 0, "emulated", "", {"nightly", "duty=0.3"});
    RunRecord a2 = MakeRun("a2", 0, "emulated", "", {"nightly"});
    a2.controller = "hysteresis";
    RunRecord a3 = MakeRun("a3", 0, "usb", "", {});
    alice_ = Submit(*store_, {a1, a2, a3}, "alice", &batch_a_);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    RunRecord b1 = MakeRun("b1", 0, "emulated", "", {"duty=0.3"});
    b1.controller = "fuzzy";
    bob_ = Submit(*store_, {b1, MakeRun("b2")}, "bob", &batch_b_);
    EXPECT_EQ(ClaimId(*store_, "usb", "usb-7"), alice_[2]);
    bob_submitted_ = store_->GetRun(bob_[0])->submitted_unix_s;
  }

  std::vector<std::int64_t> Ids(const RunFilter& f) {
    auto runs = store_->ListRuns(f);
    EXPECT_TRUE(runs.ok()) << runs.status().ToString();
    std::vector<std::int64_t> out;
    if (runs.ok()) {
      for (const auto& r : *runs) out.push_back(r.id);
    }
    return out;
  }

  std::vector<std::int64_t> alice_, bob_;
  std::int64_t batch_a_ = 0, batch_b_ = 0;
  double bob_submitted_ = 0;
};
VB_ENGINES(StoreListTest);

TEST_P(StoreListTest, NoFilterListsAllInIdOrder) {
  EXPECT_EQ(Ids({}), (std::vector<std::int64_t>{alice_[0], alice_[1], alice_[2], bob_[0], bob_[1]}));
  auto runs = store_->ListRuns({});
  EXPECT_EQ((*runs)[0].tags, (std::vector<std::string>{"nightly", "duty=0.3"}));
}

TEST_P(StoreListTest, Filters) {
  RunFilter f;
  f.status = RunStatus::kRunning;
  EXPECT_EQ(Ids(f), (std::vector<std::int64_t>{alice_[2]}));
  f = {};
  f.status = RunStatus::kQueued;
  EXPECT_EQ(Ids(f), (std::vector<std::int64_t>{alice_[0], alice_[1], bob_[0], bob_[1]}));
  f = {};
  f.tag = "duty=0.3";
  EXPECT_EQ(Ids(f), (std::vector<std::int64_t>{alice_[0], bob_[0]}));
  f.tag = "nightly";
  EXPECT_EQ(Ids(f), (std::vector<std::int64_t>{alice_[0], alice_[1]}));
  f.tag = "nope";
  EXPECT_TRUE(Ids(f).empty());
  f = {};
  f.batch_id = batch_b_;
  EXPECT_EQ(Ids(f), bob_);
  f = {};
  f.controller = "hysteresis";
  EXPECT_EQ(Ids(f), (std::vector<std::int64_t>{alice_[1]}));
  f = {};
  f.bench_name = "usb-7";
  EXPECT_EQ(Ids(f), (std::vector<std::int64_t>{alice_[2]}));
  f = {};
  f.submitter = "bob";
  EXPECT_EQ(Ids(f), bob_);
  f = {};
  f.submitted_after_unix_s = bob_submitted_;  // inclusive
  EXPECT_EQ(Ids(f), bob_);
  f = {};
  f.submitted_before_unix_s = bob_submitted_;  // exclusive
  EXPECT_EQ(Ids(f), alice_);
  // Combined: alice's nightly runs with the pi controller, queued.
  f = {};
  f.submitter = "alice";
  f.tag = "nightly";
  f.controller = "pi_current";
  f.status = RunStatus::kQueued;
  f.batch_id = batch_a_;
  EXPECT_EQ(Ids(f), (std::vector<std::int64_t>{alice_[0]}));
  f.submitter = "bob";
  EXPECT_TRUE(Ids(f).empty());
}

TEST_P(StoreListTest, Paging) {
  std::vector<std::int64_t> all;
  RunFilter f;
  f.limit = 2;
  int pages = 0;
  while (true) {
    auto page = Ids(f);
    if (page.empty()) break;
    EXPECT_LE(page.size(), 2u);
    all.insert(all.end(), page.begin(), page.end());
    f.after_id = page.back();
    ++pages;
  }
  EXPECT_EQ(pages, 3);
  EXPECT_EQ(all, (std::vector<std::int64_t>{alice_[0], alice_[1], alice_[2], bob_[0], bob_[1]}));
  // Paging combines with filters.
  f = {};
  f.limit = 1;
  f.tag = "duty=0.3";
  EXPECT_EQ(Ids(f), (std::vector<std::int64_t>{alice_[0]}));
  f.after_id = alice_[0];
  EXPECT_EQ(Ids(f), (std::vector<std::int64_t>{bob_[0]}));
}

TEST_P(StoreListTest, BadFilterNamesTheField) {
  RunFilter f;
  f.limit = 0;
  auto r = store_->ListRuns(f);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("filter.limit"), std::string::npos);
  f.limit = 1001;
  EXPECT_FALSE(store_->ListRuns(f).ok());
  f = {};
  f.after_id = -1;
  EXPECT_NE(store_->ListRuns(f).status().message().find("filter.after_id"), std::string::npos);
  f = {};
  f.submitted_before_unix_s = std::nan("");
  EXPECT_NE(store_->ListRuns(f).status().message().find("filter.submitted_before_unix_s"), std::string::npos);
}

TEST_P(StoreConnectionsTest, TwoStoresOnOneDatabaseSeeEachOthersCommits) {
  auto writer = OpenAnother();
  auto reader = OpenAnother();
  auto ids = Submit(*writer, {MakeRun("a")});
  auto run = reader->GetRun(ids[0]);
  ASSERT_TRUE(run.ok());
  EXPECT_EQ(run->status, RunStatus::kQueued);
  EXPECT_EQ(ClaimId(*reader), ids[0]);
  EXPECT_EQ(writer->GetRun(ids[0])->status, RunStatus::kRunning);
}

// ---- traces ----

bool BitEqual(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0);
}

TEST_P(StoreTraceTest, RoundTripIsBitExact) {
  Store* store = &this->store();
  auto ids = Submit(*store, {MakeRun("a")});
  ClaimId(*store);
  const std::vector<std::string> channels = {"t_s", "gate", "v_coil_V", "i_A", "x_m", "ref"};
  std::vector<TraceChunk> chunks;
  for (int k = 0; k < 3; ++k) chunks.push_back(MakeChunk(k, 500 + 7 * k, channels, 100 + k));
  // Values that must survive bit for bit: NaNs with payloads and sign, signed zero, infinities, subnormals.
  chunks[1].data[0] = std::bit_cast<double>(std::uint64_t{0x7ff8dead0000beefULL});
  chunks[1].data[1] = std::bit_cast<double>(std::uint64_t{0xfff0000000000001ULL});  // signalling NaN, negative
  chunks[1].data[2] = -0.0;
  chunks[1].data[3] = std::numeric_limits<double>::infinity();
  chunks[1].data[4] = -std::numeric_limits<double>::infinity();
  chunks[1].data[5] = std::numeric_limits<double>::denorm_min();
  chunks[1].data[6] = std::numeric_limits<double>::max();
  for (const auto& c : chunks) ASSERT_TRUE(store->AppendTraceChunk(vb::db::testing::CurrentLease(store, ids[0]), c).ok());

  auto back = store->ReadTrace(ids[0]);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  ASSERT_EQ(back->size(), chunks.size());
  for (std::size_t k = 0; k < chunks.size(); ++k) {
    const TraceChunk& got = (*back)[k];
    EXPECT_EQ(got.index, chunks[k].index);
    EXPECT_EQ(got.t0_s, chunks[k].t0_s);
    EXPECT_EQ(got.sample_period_s, chunks[k].sample_period_s);
    EXPECT_EQ(got.samples, chunks[k].samples);
    EXPECT_EQ(got.channels, channels);
    EXPECT_TRUE(BitEqual(got.data, chunks[k].data)) << "chunk " << k;
  }
}

TEST_P(StoreTraceTest, Codec0BlobIsLittleEndianChannelMajorFloat64) {
  // Chunks written before schema v4 hold raw float64 (codec 0): the store reads that layout, byte for byte.
  std::int64_t id = 0;
  {
    auto store = OpenAnother();
    id = Submit(*store, {MakeRun("a")})[0];
    ASSERT_EQ(ClaimId(*store), id);  // only the attempt holding a run writes its trace
  }
  {
    // 1.0 = 0x3FF0000000000000, little-endian: 00 00 00 00 00 00 F0 3F. a: 1, 2; b: -1, 0.5
    const char* hex = "000000000000F03F0000000000000040000000000000F0BF000000000000E03F";
    RawExec(Cat("INSERT INTO trace_chunks (run_id, idx, t0, period, samples, channels, data, codec) VALUES (", id,
                ", 0, 0.0, 0.001, 2, 'a' || ", postgres() ? "chr(10)" : "char(10)", " || 'b', ",
                postgres() ? Cat("decode('", hex, "', 'hex')") : Cat("X'", hex, "'"), ", 0)"));
  }
  auto store = OpenAnother();
  auto back = store->ReadTrace(id);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  ASSERT_EQ(back->size(), 1u);
  EXPECT_EQ((*back)[0].channels, (std::vector<std::string>{"a", "b"}));
  EXPECT_EQ((*back)[0].data, (std::vector<double>{1.0, 2.0, -1.0, 0.5}));
  // What the store writes now is codec 1, channels joined by a newline.
  TraceChunk c = (*back)[0];
  c.index = 1;
  ASSERT_TRUE(store->AppendTraceChunk(vb::db::testing::CurrentLease(store, id), c).ok());
  EXPECT_EQ(RawInt(Cat("SELECT codec FROM trace_chunks WHERE run_id = ", id, " AND idx = 1")), 1);
  EXPECT_EQ(RawText("SELECT channels FROM trace_chunks WHERE idx = 1"), "a\nb");
}

TEST_P(StoreTraceTest, BadChunksAreRejectedAndStoredOnesKept) {
  Store* store = &this->store();
  auto ids = Submit(*store, {MakeRun("a")});
  ASSERT_EQ(ClaimId(*store), ids[0]);
  const std::vector<std::string> ch = {"i_A", "x_m"};
  const TraceChunk first = MakeChunk(0, 10, ch, 1);
  ASSERT_TRUE(store->AppendTraceChunk(vb::db::testing::CurrentLease(store, ids[0]), first).ok());

  TraceChunk wrong_size = MakeChunk(3, 10, ch, 2);
  wrong_size.data.pop_back();
  Status s = store->AppendTraceChunk(vb::db::testing::CurrentLease(store, ids[0]), wrong_size);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("trace chunk 3: channels.size() * samples != data.size()"), std::string::npos)
      << s.message();

  s = store->AppendTraceChunk(vb::db::testing::CurrentLease(store, ids[0]), MakeChunk(2, 10, ch, 3));  // skips 1
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("trace chunk 2: index must be 1"), std::string::npos) << s.message();

  s = store->AppendTraceChunk(vb::db::testing::CurrentLease(store, ids[0]), MakeChunk(0, 10, ch, 4));  // repeats 0
  EXPECT_EQ(s.code(), StatusCode::kAlreadyExists);
  EXPECT_NE(s.message().find("trace chunk 0: already stored"), std::string::npos) << s.message();

  s = store->AppendTraceChunk(vb::db::testing::CurrentLease(store, ids[0]), MakeChunk(1, 10, {"i_A", "v_coil_V"}, 5));
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("trace chunk 1: channels differ"), std::string::npos) << s.message();

  struct Case {
    TraceChunk chunk;
    std::string message;
  };
  std::vector<Case> cases;
  cases.push_back({MakeChunk(-1, 10, ch, 6), "trace chunk -1: index must be >= 0"});
  {
    TraceChunk c = MakeChunk(1, 10, ch, 6);
    c.samples = 0;
    c.data.clear();
    cases.push_back({c, "trace chunk 1: samples must be > 0"});
  }
  cases.push_back({MakeChunk(1, 10, {}, 6), "trace chunk 1: channels must not be empty"});
  cases.push_back({MakeChunk(1, 10, {"i_A", ""}, 6), "trace chunk 1: channels[1] must not be empty"});
  cases.push_back({MakeChunk(1, 10, {"i_A", "i_A"}, 6), "trace chunk 1: channels[1]: duplicate channel"});
  cases.push_back({MakeChunk(1, 10, {"i\nA"}, 6), "trace chunk 1: channels[0] must not contain a newline"});
  {
    TraceChunk c = MakeChunk(1, 10, ch, 6);
    c.sample_period_s = 0;
    cases.push_back({c, "trace chunk 1: sample_period_s must be finite and > 0"});
    c = MakeChunk(1, 10, ch, 6);
    c.t0_s = std::numeric_limits<double>::infinity();
    cases.push_back({c, "trace chunk 1: t0_s must be finite"});
  }
  for (const Case& c : cases) {
    Status bad = store->AppendTraceChunk(vb::db::testing::CurrentLease(store, ids[0]), c.chunk);
    EXPECT_EQ(bad.code(), StatusCode::kInvalidArgument) << c.message;
    EXPECT_NE(bad.message().find(c.message), std::string::npos) << bad.message();
  }

  auto back = store->ReadTrace(ids[0]);
  ASSERT_TRUE(back.ok());
  ASSERT_EQ(back->size(), 1u);
  EXPECT_TRUE(BitEqual((*back)[0].data, first.data));
  EXPECT_TRUE(store->AppendTraceChunk(vb::db::testing::CurrentLease(store, ids[0]), MakeChunk(1, 10, ch, 7)).ok());
  EXPECT_EQ(store->ReadTrace(ids[0])->size(), 2u);
}

TEST_P(StoreTraceTest, TracesOfDifferentRunsAreSeparate) {
  Store* store = &this->store();
  auto ids = Submit(*store, {MakeRun("a"), MakeRun("b")});
  ASSERT_EQ(ClaimId(*store, "emulated", "bench-1"), ids[0]);
  ASSERT_EQ(ClaimId(*store, "emulated", "bench-2"), ids[1]);
  ASSERT_TRUE(store->AppendTraceChunk(vb::db::testing::CurrentLease(store, ids[0]), MakeChunk(0, 5, {"a"}, 1)).ok());
  ASSERT_TRUE(store->AppendTraceChunk(vb::db::testing::CurrentLease(store, ids[1]), MakeChunk(0, 6, {"b"}, 2)).ok());
  ASSERT_TRUE(store->AppendTraceChunk(vb::db::testing::CurrentLease(store, ids[0]), MakeChunk(1, 5, {"a"}, 3)).ok());
  EXPECT_EQ(store->ReadTrace(ids[0])->size(), 2u);
  EXPECT_EQ(store->ReadTrace(ids[1])->size(), 1u);
  EXPECT_EQ(store->ReadTrace(ids[1])->at(0).samples, 6);
}

}  // namespace
}  // namespace vb::db

namespace vb::db {
namespace {

// The streaming read hands chunks over in order with the total length, and stops at the callback's error.
TEST_P(StoreTraceTest, ForEachTraceChunkStreamsInOrderAndStopsOnError) {
  Store* store = &this->store();
  auto ids = Submit(*store, {MakeRun("a")});
  ASSERT_EQ(ClaimId(*store), ids[0]);
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(store->AppendTraceChunk(vb::db::testing::CurrentLease(store, ids[0]), MakeChunk(k, 7, {"i_A", "x_m"}, k)).ok());
  std::vector<std::int32_t> seen;
  ASSERT_TRUE(store->ForEachTraceChunk(ids[0], [&](const TraceChunk& c, std::int64_t total) {
                     EXPECT_EQ(total, 21);
                     EXPECT_EQ(c.data, MakeChunk(c.index, 7, {"i_A", "x_m"}, c.index).data);
                     seen.push_back(c.index);
                     return Status::Ok();
                   }).ok());
  EXPECT_EQ(seen, (std::vector<std::int32_t>{0, 1, 2}));
  int calls = 0;
  Status st = store->ForEachTraceChunk(ids[0], [&](const TraceChunk&, std::int64_t) {
    return ++calls == 2 ? Status::Aborted("stop here") : Status::Ok();
  });
  EXPECT_EQ(st.code(), StatusCode::kAborted);
  EXPECT_EQ(calls, 2);
  EXPECT_EQ(store->ForEachTraceChunk(4242, [](const TraceChunk&, std::int64_t) { return Status::Ok(); }).code(),
            StatusCode::kNotFound);
}

}  // namespace
}  // namespace vb::db
