// benchctl db copy's engine (db/pg_copy.h): a SQLite store with every kind of row (runs with sweep points,
// repeats, splits and tags; finished, failed, cancelled, interrupted and queued runs; metrics with a NaN; traces
// in both codecs; two baseline versions; a regression night) copied into PostgreSQL reads back identical
// through the Store API, ids included; a non-empty target and a source with running runs are refused, changing
// nothing; and benchctl db copy / db info drive it with the house exit codes.
#include "db/pg_copy.h"

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>

#include "db/open_store.h"
#include "db/sqlite_store.h"
#include "db/store.h"
#include "db/testing.h"
#include "db/text.h"
#include "tests/db/pg_server.h"
#include "tests/db/store_engines.h"

namespace vb::db {
namespace {

std::string TempFile(const std::string& name) {
  const std::string path = Cat(::testing::TempDir(), "vb_pg_copy_", getpid(), "_", name, ".db");
  for (const char* suffix : {"", "-wal", "-shm"}) std::remove((path + suffix).c_str());
  return path;
}

TraceChunk Chunk(std::int32_t index, std::int32_t samples, double phase) {
  TraceChunk c;
  c.index = index;
  c.t0_s = index * samples * 1e-4;
  c.sample_period_s = 1e-4;
  c.samples = samples;
  c.channels = {"t_s", "i_A", "gate"};
  c.data.resize(3 * static_cast<std::size_t>(samples));
  for (std::int32_t k = 0; k < samples; ++k) {
    c.data[static_cast<std::size_t>(k)] = c.t0_s + k * 1e-4;
    c.data[static_cast<std::size_t>(samples + k)] = std::sin(phase + 0.01 * k);
    c.data[static_cast<std::size_t>(2 * samples + k)] = (k / 17) % 2;
  }
  return c;
}

// Fills a SQLite store with one of everything. Returns the run ids.
std::vector<std::int64_t> Populate(Store& s) {
  RunRecord swept;
  swept.key = RunKey{"m/pi", {{"conditions.supply_V", 24.0}, {"x", 0.1 + 0.2}}, 2};
  swept.controller = "pi_current";
  swept.bench_kind = "emulated";
  swept.spec_json = "{\"exact\": [1, 2.50]}\n";
  swept.priority = 3;
  swept.tags = {"nightly", "duty=0.3", "zz"};
  RunRecord imported = swept;
  imported.key = NamedRun("r07");
  imported.split = "holdout";
  imported.t_start_s = 12.5;
  imported.tags = {};
  imported.requeue_on_interrupt = false;
  RunRecord plain = imported;
  plain.key = NamedRun("plain");
  plain.split = "";
  plain.t_start_s = std::nan("");
  RunRecord waiting = plain;
  waiting.key = NamedRun("waiting");
  waiting.requeue_on_interrupt = true;
  RunRecord cancelled = plain;
  cancelled.key = NamedRun("cancelled");
  std::vector<std::int64_t> ids;
  EXPECT_TRUE(s.SubmitBatch("alice", "b1", "{\"batch\": 1}", {swept, imported}, &ids).ok());
  std::vector<std::int64_t> more;
  EXPECT_TRUE(s.SubmitBatch("bob", "b2", "{}", {plain, waiting, cancelled}, &more).ok());
  ids.insert(ids.end(), more.begin(), more.end());
  // ids[0]: done with metrics (one NaN) and a 3-chunk trace; ids[1]: failed; ids[2]: interrupted (not re-queued);
  // ids[3]: queued; ids[4]: cancelled while queued.
  auto c0 = s.ClaimNext(BenchClaim("emulated", "bench-a"));
  EXPECT_TRUE(c0.ok() && c0->has_value() && (*c0)->id == ids[0]);
  for (int k = 0; k < 3; ++k) EXPECT_TRUE(s.AppendTraceChunk(LeaseOf(**c0), Chunk(k, 500, k)).ok());
  EXPECT_TRUE(s.SetProgress(LeaseOf(**c0), 0.5).ok());
  ExecutionRecord paced;  // a paced run's execution with its loop statistics (schema v6)
  paced.wall_s = 1.5;
  paced.simulated_s = 1.5;
  paced.samples = 1500;
  paced.control_ticks = 1501;
  paced.metrics_from_trajectory = true;
  paced.loop.emplace();
  paced.loop->ticks = 1501;
  paced.loop->overruns = 4;
  paced.loop->jitter_p50_s = 9.5e-6;
  paced.loop->jitter_p99_s = 7.25e-5;
  paced.loop->jitter_max_s = 2.5e-4;
  paced.build = "valvebench 0.1.0 sha256:ffeeddccbbaa99887766554433221100";  // schema v7; `unpaced` has none
  EXPECT_TRUE(s.Finish(LeaseOf(**c0), RunStatus::kDone, "",
                       {{"rmse_A", 1.25e-3}, {"nan_metric", std::nan("")}, {"effort", -0.0}}, paced)
                  .ok());
  auto c1 = s.ClaimNext(BenchClaim("emulated", "bench-b"));
  EXPECT_TRUE(c1.ok() && c1->has_value());
  ExecutionRecord unpaced;  // executed, not paced: no loop statistics
  unpaced.wall_s = 0.125;
  unpaced.simulated_s = 0.25;
  unpaced.samples = 250;
  EXPECT_TRUE(s.Finish(LeaseOf(**c1), RunStatus::kFailed, "bench tripped: over-current", {}, unpaced).ok());
  auto c2 = s.ClaimNext(BenchClaim("emulated", "bench-c"));
  EXPECT_TRUE(c2.ok() && c2->has_value());
  EXPECT_TRUE(s.AppendTraceChunk(LeaseOf(**c2), Chunk(0, 10, 9)).ok());
  EXPECT_EQ(*s.RecoverAfterCrash(""), 1);  // its server stopped: interrupted for good (not re-queueable)
  EXPECT_TRUE(s.RequestCancel(ids[4], "not needed").ok());
  EXPECT_TRUE(s.SaveBaseline("main", "local batch 1", "first", {{"m/pi", "rmse_A", 1e-3, 1e-5, 3}}).ok());
  EXPECT_TRUE(s.SaveBaseline("main", "local batch 1", "second",
                             {{"m/pi", "rmse_A", 2e-3, 0, 1}, {"m/pi", "effort", 3.5, 0.25, 2}})
                  .ok());
  RegressionRecord night;
  night.suite = "ci";
  night.baseline_name = "main";
  night.baseline_version = 2;
  night.batch_id = 1;
  night.night = "2026-11-24";
  night.verdict = "regressed";
  night.result_json = "{\"cases\": []}";
  EXPECT_TRUE(s.SaveRegression(night).ok());
  return ids;
}

bool SameDouble(double a, double b) { return (std::isnan(a) && std::isnan(b)) || std::memcmp(&a, &b, 8) == 0; }

void ExpectSameRun(const RunRecord& a, const RunRecord& b) {
  EXPECT_EQ(a.id, b.id);
  EXPECT_EQ(a.batch_id, b.batch_id);
  EXPECT_EQ(a.key, b.key);
  EXPECT_EQ(a.controller, b.controller);
  EXPECT_EQ(a.bench_kind, b.bench_kind);
  EXPECT_EQ(a.bench_name, b.bench_name);
  EXPECT_EQ(a.spec_json, b.spec_json);
  EXPECT_EQ(a.submitter, b.submitter);
  EXPECT_EQ(a.priority, b.priority);
  EXPECT_EQ(a.status, b.status);
  EXPECT_EQ(a.reason, b.reason);
  EXPECT_EQ(a.requeue_on_interrupt, b.requeue_on_interrupt);
  EXPECT_TRUE(SameDouble(a.submitted_unix_s, b.submitted_unix_s));
  EXPECT_TRUE(SameDouble(a.started_unix_s, b.started_unix_s));
  EXPECT_TRUE(SameDouble(a.finished_unix_s, b.finished_unix_s));
  EXPECT_TRUE(SameDouble(a.progress, b.progress));
  EXPECT_EQ(a.tags, b.tags);
  EXPECT_EQ(a.split, b.split);
  EXPECT_TRUE(SameDouble(a.t_start_s, b.t_start_s));
  ASSERT_EQ(a.execution.has_value(), b.execution.has_value());
  if (!a.execution) return;
  EXPECT_TRUE(SameDouble(a.execution->wall_s, b.execution->wall_s));
  EXPECT_TRUE(SameDouble(a.execution->simulated_s, b.execution->simulated_s));
  EXPECT_EQ(a.execution->samples, b.execution->samples);
  EXPECT_EQ(a.execution->control_ticks, b.execution->control_ticks);
  EXPECT_EQ(a.execution->metrics_from_trajectory, b.execution->metrics_from_trajectory);
  EXPECT_EQ(a.execution->build, b.execution->build);
  ASSERT_EQ(a.execution->loop.has_value(), b.execution->loop.has_value());
  if (!a.execution->loop) return;
  EXPECT_EQ(a.execution->loop->ticks, b.execution->loop->ticks);
  EXPECT_EQ(a.execution->loop->overruns, b.execution->loop->overruns);
  EXPECT_TRUE(SameDouble(a.execution->loop->jitter_p50_s, b.execution->loop->jitter_p50_s));
  EXPECT_TRUE(SameDouble(a.execution->loop->jitter_p99_s, b.execution->loop->jitter_p99_s));
  EXPECT_TRUE(SameDouble(a.execution->loop->jitter_max_s, b.execution->loop->jitter_max_s));
}

class PgCopyTest : public ::testing::Test {
 protected:
  void SetUp() override {
    server_ = testing::PgServer::Get();
    if (server_ == nullptr) GTEST_SKIP() << "PostgreSQL cannot start here: " << testing::PgServer::WhyUnavailable();
    auto db = server_->CreateDatabase();
    ASSERT_TRUE(db.ok()) << db.status().ToString();
    target_ = *db;
    source_ = TempFile(::testing::UnitTest::GetInstance()->current_test_info()->name());
  }
  void TearDown() override {
    for (const char* suffix : {"", "-wal", "-shm"}) std::remove((source_ + suffix).c_str());
  }
  testing::PgServer* server_ = nullptr;
  std::string target_, source_;
};

TEST_F(PgCopyTest, EverythingReadsBackIdenticalWithItsIds) {
  std::vector<std::int64_t> ids;
  {
    auto s = OpenSqliteStore(source_);
    ASSERT_TRUE(s.ok());
    ids = Populate(**s);
    auto c = (*s)->ClaimNext(BenchClaim("emulated", "bench-c"));  // nothing left for it but "waiting"
    ASSERT_TRUE(c.ok() && c->has_value());
    ASSERT_EQ(*(*s)->RecoverAfterCrash(""), 1);  // ids[3] queued again, with an interruption in its history
  }
  {
    // A chunk an older build stored raw (codec 0), as the file keeps it.
    sqlite3* raw = nullptr;
    ASSERT_EQ(sqlite3_open(source_.c_str(), &raw), SQLITE_OK);
    ASSERT_EQ(sqlite3_exec(raw,
                           Cat("INSERT INTO trace_chunks (run_id, idx, t0, period, samples, channels, data, codec) "
                               "VALUES (",
                               ids[1], ", 0, 0.0, 0.001, 1, 'a', X'000000000000F03F', 0)")
                               .c_str(),
                           nullptr, nullptr, nullptr),
              SQLITE_OK);
    sqlite3_close(raw);
  }
  auto summary = CopySqliteToPostgres(source_, target_, {});
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  std::map<std::string, std::int64_t> rows(summary->rows.begin(), summary->rows.end());
  EXPECT_EQ(rows["runs"], 5);
  EXPECT_EQ(rows["batches"], 2);
  EXPECT_EQ(rows["trace_chunks"], 5);  // 3 of the done run, the interrupted run's 1 (kept), the codec-0 one
  EXPECT_EQ(rows["baselines"], 2);
  EXPECT_EQ(rows["baseline_metrics"], 3);
  EXPECT_EQ(rows["regressions"], 1);
  EXPECT_EQ(rows["run_tags"], 3);
  EXPECT_EQ(rows["run_sweep"], 2);
  EXPECT_GT(summary->trace_bytes, 0);

  auto a = OpenSqliteStore(source_);
  auto b = OpenStore(target_);
  ASSERT_TRUE(a.ok() && b.ok());
  Store& src = **a;
  Store& dst = **b;
  RunFilter all;
  all.limit = 1000;
  auto ra = src.ListRuns(all);
  auto rb = dst.ListRuns(all);
  ASSERT_TRUE(ra.ok() && rb.ok());
  ASSERT_EQ(ra->size(), rb->size());
  for (std::size_t k = 0; k < ra->size(); ++k) {
    SCOPED_TRACE(Cat("run ", (*ra)[k].id));
    ExpectSameRun((*ra)[k], (*rb)[k]);
    const std::int64_t id = (*ra)[k].id;
    auto ha = src.History(id);
    auto hb = dst.History(id);
    ASSERT_TRUE(ha.ok() && hb.ok());
    ASSERT_EQ(ha->size(), hb->size());
    for (std::size_t h = 0; h < ha->size(); ++h) {
      EXPECT_EQ((*ha)[h].status, (*hb)[h].status);
      EXPECT_TRUE(SameDouble((*ha)[h].at_unix_s, (*hb)[h].at_unix_s));
      EXPECT_EQ((*ha)[h].reason, (*hb)[h].reason);
    }
    auto ma = src.GetMetrics(id);
    auto mb = dst.GetMetrics(id);
    ASSERT_TRUE(ma.ok() && mb.ok());
    ASSERT_EQ(ma->size(), mb->size());
    for (std::size_t m = 0; m < ma->size(); ++m) {
      EXPECT_EQ((*ma)[m].name, (*mb)[m].name);
      EXPECT_TRUE(SameDouble((*ma)[m].value, (*mb)[m].value)) << (*ma)[m].name;
    }
    auto ta = src.ReadTrace(id);
    auto tb = dst.ReadTrace(id);
    ASSERT_TRUE(ta.ok() && tb.ok()) << tb.status().ToString();
    ASSERT_EQ(ta->size(), tb->size());
    for (std::size_t c = 0; c < ta->size(); ++c) {
      EXPECT_EQ((*ta)[c].channels, (*tb)[c].channels);
      EXPECT_EQ((*ta)[c].samples, (*tb)[c].samples);
      EXPECT_TRUE(SameDouble((*ta)[c].t0_s, (*tb)[c].t0_s));
      ASSERT_EQ((*ta)[c].data.size(), (*tb)[c].data.size());
      EXPECT_EQ(std::memcmp((*ta)[c].data.data(), (*tb)[c].data.data(), (*ta)[c].data.size() * 8), 0);
    }
  }
  // The statuses the source had: done, failed, interrupted, queued (re-queued), cancelled.
  EXPECT_EQ((*rb)[0].status, RunStatus::kDone);
  EXPECT_EQ((*rb)[2].status, RunStatus::kInterrupted);
  // The execution columns travelled: the paced run's loop statistics, the unpaced run's none, the rest nothing.
  ASSERT_TRUE((*rb)[0].execution && (*rb)[0].execution->loop);
  EXPECT_EQ((*rb)[0].execution->loop->overruns, 4);
  ASSERT_TRUE((*rb)[1].execution.has_value());
  EXPECT_FALSE((*rb)[1].execution->loop.has_value());
  EXPECT_FALSE((*rb)[2].execution.has_value());
  EXPECT_EQ(dst.ReadTrace(ids[1])->at(0).data, std::vector<double>{1.0});  // codec 0, as stored
  auto stored_a = src.StoredTraceBytes("alice");
  auto stored_b = dst.StoredTraceBytes("alice");
  ASSERT_TRUE(stored_a.ok() && stored_b.ok());
  EXPECT_EQ(*stored_a, *stored_b);

  auto la = src.ListBaselines();
  auto lb = dst.ListBaselines();
  ASSERT_TRUE(la.ok() && lb.ok());
  ASSERT_EQ(lb->size(), 2u);
  for (std::int32_t v : {1, 2}) {
    auto ba = src.GetBaseline("main", v);
    auto bb = dst.GetBaseline("main", v);
    ASSERT_TRUE(ba.ok() && bb.ok());
    EXPECT_EQ(ba->note, bb->note);
    EXPECT_EQ(ba->source, bb->source);
    EXPECT_TRUE(SameDouble(ba->created_unix_s, bb->created_unix_s));
    ASSERT_EQ(ba->entries.size(), bb->entries.size());
    for (std::size_t e = 0; e < ba->entries.size(); ++e) {
      EXPECT_EQ(ba->entries[e].case_name, bb->entries[e].case_name);
      EXPECT_EQ(ba->entries[e].metric, bb->entries[e].metric);
      EXPECT_TRUE(SameDouble(ba->entries[e].mean, bb->entries[e].mean));
      EXPECT_TRUE(SameDouble(ba->entries[e].spread, bb->entries[e].spread));
      EXPECT_EQ(ba->entries[e].n, bb->entries[e].n);
    }
  }
  auto ga = src.GetRegression(1);
  auto gb = dst.GetRegression(1);
  ASSERT_TRUE(ga.ok() && gb.ok());
  EXPECT_EQ(ga->night, gb->night);
  EXPECT_EQ(ga->verdict, gb->verdict);
  EXPECT_EQ(ga->result_json, gb->result_json);
  EXPECT_EQ(ga->batch_id, gb->batch_id);

  // The sequences moved past the copied ids: new rows get new ids, and the copied queue works.
  std::vector<std::int64_t> fresh;
  RunRecord r = (*ra)[0];
  r.tags = {};
  r.submitter = "";
  ASSERT_TRUE(dst.SubmitBatch("carol", "b3", "{}", {r}, &fresh).ok());
  EXPECT_EQ(fresh[0], ids.back() + 1);
  EXPECT_EQ(*dst.SaveBaseline("main", "", "third", {{"c", "m", 1, 0, 1}}), 3);
  RegressionRecord reg = *ga;
  reg.id = 0;
  EXPECT_EQ(*dst.SaveRegression(reg), 2);
  auto claimed = dst.ClaimNext(BenchClaim("emulated", "bench-z"));
  ASSERT_TRUE(claimed.ok() && claimed->has_value());
  EXPECT_EQ((*claimed)->id, ids[3]);  // the re-queued run (priority 3) before the fresh one
}

TEST_F(PgCopyTest, ANonEmptyTargetOrARunningSourceIsRefusedAndNothingIsCopied) {
  {
    auto s = OpenSqliteStore(source_);
    ASSERT_TRUE(s.ok());
    Populate(**s);
  }
  ASSERT_TRUE(CopySqliteToPostgres(source_, target_, {}).ok());
  auto again = CopySqliteToPostgres(source_, target_, {});
  ASSERT_FALSE(again.ok());
  EXPECT_EQ(again.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(again.status().message().find("already holds"), std::string::npos) << again.status().message();
  // Told to add to it, the same ids collide: refused as a whole.
  auto forced = CopySqliteToPostgres(source_, target_, {true});
  ASSERT_FALSE(forced.ok());
  EXPECT_EQ(forced.status().code(), StatusCode::kAlreadyExists) << forced.status().ToString();
  auto info = ReadStoreInfo(target_);
  ASSERT_TRUE(info.ok()) << info.status().ToString();
  std::map<std::string, std::int64_t> rows(info->rows.begin(), info->rows.end());
  EXPECT_EQ(rows["runs"], 5);  // the first copy's, nothing more
  EXPECT_EQ(info->engine, "postgresql");
  EXPECT_EQ(info->schema_version, 7);

  // A source with a running run: refused (its server is still using it).
  const std::string busy = TempFile("busy");
  {
    auto s = OpenSqliteStore(busy);
    ASSERT_TRUE(s.ok());
    Populate(**s);
    ASSERT_TRUE((*s)->ClaimNext(BenchClaim("emulated", "bench-x")).ok());
  }
  auto fresh = server_->CreateDatabase();
  ASSERT_TRUE(fresh.ok());
  auto refused = CopySqliteToPostgres(busy, *fresh, {});
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(refused.status().message().find("running"), std::string::npos);
  for (const char* suffix : {"", "-wal", "-shm"}) std::remove((busy + suffix).c_str());

  EXPECT_EQ(CopySqliteToPostgres(source_, "not-a-url.db", {}).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(CopySqliteToPostgres("/nonexistent/x.db", target_, {}).status().code(), StatusCode::kNotFound);
}

// ---- benchctl db copy / db info ----

struct Ran {
  int code = -1;
  std::string out;
};

Ran Benchctl(const std::string& args) {
  const std::string out_file = Cat(::testing::TempDir(), "vb_pg_copy_out_", getpid(), ".txt");
  const int rc = std::system(Cat(VB_BENCHCTL, " ", args, " > ", out_file, " 2>&1").c_str());
  std::ifstream in(out_file);
  Ran r;
  r.out.assign(std::istreambuf_iterator<char>(in), {});
  std::remove(out_file.c_str());
  r.code = WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  return r;
}

TEST_F(PgCopyTest, BenchctlDbCopyAndInfoWithExitCodes) {
  {
    auto s = OpenSqliteStore(source_);
    ASSERT_TRUE(s.ok());
    Populate(**s);
  }
  const std::string to = Cat("'", target_, "'");
  Ran copied = Benchctl(Cat("db copy --from ", source_, " --to ", to, " --json"));
  ASSERT_EQ(copied.code, 0) << copied.out;
  auto j = nlohmann::json::parse(copied.out, nullptr, false);
  ASSERT_FALSE(j.is_discarded()) << copied.out;
  EXPECT_EQ(j["rows"]["runs"], 5);
  EXPECT_EQ(j["rows"]["trace_chunks"], 4);
  EXPECT_EQ(j["target_schema_version"], 7);

  Ran again = Benchctl(Cat("db copy --from ", source_, " --to ", to));
  EXPECT_EQ(again.code, 2) << again.out;  // refused: the target is not empty
  EXPECT_NE(again.out.find("already holds"), std::string::npos) << again.out;

  Ran info = Benchctl(Cat("db info --db ", to, " --json"));
  ASSERT_EQ(info.code, 0) << info.out;
  auto ij = nlohmann::json::parse(info.out, nullptr, false);
  ASSERT_FALSE(ij.is_discarded()) << info.out;
  EXPECT_EQ(ij["engine"], "postgresql");
  EXPECT_EQ(ij["schema_version"], 7);
  EXPECT_EQ(ij["runs_by_status"]["done"], 1);
  EXPECT_EQ(ij["rows"]["baselines"], 2);

  Ran sqlite_info = Benchctl(Cat("db info --db ", source_));
  ASSERT_EQ(sqlite_info.code, 0) << sqlite_info.out;
  EXPECT_NE(sqlite_info.out.find("engine          sqlite"), std::string::npos) << sqlite_info.out;

  Ran unreachable = Benchctl("db info --db 'host=/nonexistent-vb-dir dbname=x'");
  EXPECT_EQ(unreachable.code, 3) << unreachable.out;
  Ran missing = Benchctl("db copy --from /nonexistent/x.db --to 'dbname=x'");
  EXPECT_EQ(missing.code, 2) << missing.out;
}

}  // namespace
}  // namespace vb::db
