// The PostgreSQL store when the database fails (docs/lab.md, "When the database fails"; issue 30): the first
// call after the hosts' sessions were terminated or the server restarted runs on a new connection instead of
// failing; an outage is Unavailable ("store unavailable: ...", never the statement's text) until the server is
// back; a server that does not answer at all (a stopped backend) is seen by the client's deadline; every
// connection carries the timeouts. A binary of its own: these tests restart and stop the process's server.
#include <gtest/gtest.h>

#include <signal.h>
#include <sys/types.h>

#include <string>
#include <vector>

#include "db/open_store.h"
#include "db/pg_conn.h"
#include "db/store.h"
#include "db/text.h"
#include "tests/db/pg_server.h"

namespace vb::db {
namespace {

using testing::PgServer;

class PgFaultsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    server_ = PgServer::Get();
    if (server_ == nullptr) GTEST_SKIP() << "PostgreSQL unavailable: " << PgServer::WhyUnavailable();
    auto loc = server_->CreateDatabase();
    ASSERT_TRUE(loc.ok()) << loc.status().ToString();
    location_ = *loc;
    auto conn = pg::Connection::Open(location_);
    ASSERT_TRUE(conn.ok()) << conn.status().ToString();
    auto name = (*conn)->Exec("SELECT current_database()::text");
    ASSERT_TRUE(name.ok()) << name.status().ToString();
    dbname_ = name->Text(0, 0);
  }

  std::vector<std::int64_t> Submit(Store* store, int n) {
    std::vector<RunRecord> runs(static_cast<std::size_t>(n));
    for (int k = 0; k < n; ++k) {
      runs[static_cast<std::size_t>(k)].key = NamedRun(Cat("r", k));
      runs[static_cast<std::size_t>(k)].bench_kind = "emulated";
      runs[static_cast<std::size_t>(k)].spec_json = "{}";
    }
    std::vector<std::int64_t> ids;
    auto b = store->SubmitBatch("alice", "b", "{}", runs, &ids);
    EXPECT_TRUE(b.ok()) << b.status().ToString();
    return ids;
  }

  static ClaimRequest Claim() {
    ClaimRequest r = BenchClaim("emulated", "bench-a");
    r.host = "host-a";
    r.lease_ttl_s = 10;
    return r;
  }

  PgServer* server_ = nullptr;
  std::string location_, dbname_;
};

TEST_F(PgFaultsTest, EveryConnectionCarriesTheTimeoutsAndTheLocationsOwnWin) {
  auto conn = pg::Connection::Open(location_);
  ASSERT_TRUE(conn.ok()) << conn.status().ToString();
  auto st = (*conn)->Exec("SELECT current_setting('statement_timeout')::text, current_setting('lock_timeout')::text");
  ASSERT_TRUE(st.ok()) << st.status().ToString();
  EXPECT_EQ(st->Text(0, 0), "10s");
  EXPECT_EQ(st->Text(0, 1), "5s");
  EXPECT_DOUBLE_EQ((*conn)->deadline_s(), 10 + pg::kDeadlineMargin_s);
  auto own = pg::Connection::Open(location_ + " options='-c statement_timeout=2s'");
  ASSERT_TRUE(own.ok()) << own.status().ToString();
  EXPECT_DOUBLE_EQ((*own)->deadline_s(), 2 + pg::kDeadlineMargin_s);
  auto none = pg::Connection::Open(location_ + " options='-c statement_timeout=0'");
  ASSERT_TRUE(none.ok()) << none.status().ToString();
  EXPECT_EQ((*none)->deadline_s(), 0);
}

TEST_F(PgFaultsTest, TheFirstCallAfterTheSessionsWereTerminatedWorks) {
  auto store = OpenStore(location_);
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  const auto ids = Submit(store->get(), 2);
  // A statement on its own (the API's GetRun on a pooled connection).
  auto n = server_->TerminateSessions(dbname_);
  ASSERT_TRUE(n.ok()) << n.status().ToString();
  ASSERT_GE(*n, 1);
  auto run = (*store)->GetRun(ids[0]);
  EXPECT_TRUE(run.ok()) << run.status().ToString();
  // A transaction (a claim), and a lease write after it.
  ASSERT_TRUE(server_->TerminateSessions(dbname_).ok());
  auto claimed = (*store)->ClaimNext(Claim());
  ASSERT_TRUE(claimed.ok()) << claimed.status().ToString();
  ASSERT_TRUE(claimed->has_value());
  ASSERT_TRUE(server_->TerminateSessions(dbname_).ok());
  EXPECT_TRUE((*store)->Finish(LeaseOf(**claimed), RunStatus::kDone, "", {{"rmse_A", 1.0}}).ok());
}

TEST_F(PgFaultsTest, TheFirstCallAfterARestartWorks) {
  auto store = OpenStore(location_);
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  const auto ids = Submit(store->get(), 1);
  ASSERT_TRUE(server_->Restart().ok());
  auto run = (*store)->GetRun(ids[0]);
  EXPECT_TRUE(run.ok()) << run.status().ToString();
  ASSERT_TRUE(server_->Restart().ok());
  auto listed = (*store)->ListRuns(RunFilter{});
  EXPECT_TRUE(listed.ok()) << listed.status().ToString();
}

TEST_F(PgFaultsTest, AnOutageIsUnavailableWithoutTheStatementUntilTheServerIsBack) {
  auto store = OpenStore(location_);
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  const auto ids = Submit(store->get(), 2);
  auto claimed = (*store)->ClaimNext(Claim());
  ASSERT_TRUE(claimed.ok() && claimed->has_value());
  ASSERT_TRUE(server_->StopServer().ok());
  const Status get = (*store)->GetRun(ids[0]).status();
  const Status claim = (*store)->ClaimNext(Claim()).status();
  const Status finish = (*store)->Finish(LeaseOf(**claimed), RunStatus::kDone, "", {});
  const Status opened = OpenStore(location_).status();
  ASSERT_TRUE(server_->StartServer().ok());
  for (const Status& st : {get, claim, finish, opened}) {
    EXPECT_EQ(st.code(), StatusCode::kUnavailable) << st.ToString();
    EXPECT_EQ(ClassifyWrite(st), WriteFault::kTransient);
    EXPECT_EQ(st.message().rfind("store unavailable: ", 0), 0u) << st.message();
    EXPECT_EQ(st.message().find("SELECT"), std::string::npos) << st.message();
    EXPECT_EQ(st.message().find("UPDATE"), std::string::npos) << st.message();
  }
  // Back: the same store carries on, and the run's result is written once.
  EXPECT_TRUE((*store)->GetRun(ids[0]).ok());
  EXPECT_TRUE((*store)->Finish(LeaseOf(**claimed), RunStatus::kDone, "", {}).ok());
  EXPECT_EQ((*store)->GetRun((*claimed)->id)->status, RunStatus::kDone);
}

TEST_F(PgFaultsTest, AServerThatDoesNotAnswerIsSeenByTheDeadlineAndTheConnectionRemade) {
  // statement_timeout 1 s: the deadline on this side is 1 + kDeadlineMargin_s. The session's backend is
  // stopped, so the server cannot enforce its own timeout: only the client's deadline ends the wait.
  auto conn = pg::Connection::Open(location_ + " options='-c statement_timeout=1s'");
  ASSERT_TRUE(conn.ok()) << conn.status().ToString();
  auto pid = (*conn)->QueryInt("SELECT pg_backend_pid()::int8");
  ASSERT_TRUE(pid.ok()) << pid.status().ToString();
  ASSERT_EQ(kill(static_cast<pid_t>(*pid), SIGSTOP), 0);
  auto hung = (*conn)->QueryInt("SELECT 1::int8");
  ASSERT_EQ(kill(static_cast<pid_t>(*pid), SIGCONT), 0);
  EXPECT_EQ(hung.status().code(), StatusCode::kUnavailable) << hung.status().ToString();
  EXPECT_NE(hung.status().message().find("no answer within"), std::string::npos) << hung.status().message();
  EXPECT_FALSE((*conn)->connected());
  auto again = (*conn)->QueryInt("SELECT 2::int8");
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  EXPECT_EQ(*again, 2);
  auto new_pid = (*conn)->QueryInt("SELECT pg_backend_pid()::int8");
  ASSERT_TRUE(new_pid.ok());
  EXPECT_NE(*new_pid, *pid);
}

TEST_F(PgFaultsTest, ErrorsAreClassifiedByCodeNotText) {
  auto store = OpenStore(location_);
  ASSERT_TRUE(store.ok());
  const auto ids = Submit(store->get(), 1);
  auto claimed = (*store)->ClaimNext(Claim());
  ASSERT_TRUE(claimed.ok() && claimed->has_value());
  Lease stale = LeaseOf(**claimed);
  stale.fence += 1;
  EXPECT_EQ(ClassifyWrite((*store)->SetProgress(stale, 0.5)), WriteFault::kFenced);
  EXPECT_EQ(ClassifyWrite((*store)->SetProgress(LeaseOf(**claimed), 2.0)), WriteFault::kPermanent);
  EXPECT_EQ(ClassifyWrite((*store)->SetProgress(LeaseOf(**claimed), 0.5)), WriteFault::kNone);
  EXPECT_EQ(ClassifyWrite((*store)->SetProgress(Lease{ids[0] + 100, 1}, 0.5)), WriteFault::kFenced);
}

}  // namespace
}  // namespace vb::db
