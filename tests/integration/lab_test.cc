// The lab (docs/lab.md): two real valvebench-server hosts sharing one SQLite file. Every host lists every
// host's benches with liveness; a run executing on one host is watched and cancelled through the other; a host
// that is SIGKILLed or SIGSTOPped loses its run to the other host after the lease TTL, the run finishes exactly
// once, and the stopped host's late writes are refused and recorded.
#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <thread>

#include "client/client.h"
#include "db/sqlite_store.h"
#include "db/store.h"
#include "experiment/spec.h"
#include "server/config.h"
#include "server_process.h"

namespace vb {
namespace {

namespace v1 = valvebench::v1;
using testing::ServerProcess;
using Clock = std::chrono::steady_clock;

client::Client MakeClient(const std::string& address, const char* token) {
  client::ClientOptions o;
  o.address = address;
  o.token = token;
  o.deadline_s = 20.0;
  return client::Client(o);
}

v1::ExperimentSpec PacedRun(double duration_s) {
  auto s = experiment::ParseSpecJson(R"({"name": "lab", "duration_s": )" + std::to_string(duration_s) +
                                     R"(, "conditions": {"supply_V": 24, "supply_pressure_Pa": 400000},
      "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 100, "duty": 0.5}]}},
      "recording": {"rate_Hz": 2000}})");
  EXPECT_TRUE(s.ok()) << s.status().message();
  return *s;
}

bool Ended(v1::RunStatus s) { return s == v1::DONE || s == v1::FAILED || s == v1::CANCELLED; }

// Two hosts, each with one paced emulated bench, on one database file (host b's runs.db is a link to a's).
class LabTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string root = ::testing::TempDir() + "/vb-lab-" +
                             ::testing::UnitTest::GetInstance()->current_test_info()->name() + "-" +
                             std::to_string(::getpid());
    std::filesystem::remove_all(root);
    for (const char* h : {"a", "b"}) {
      const std::string dir = root + "/" + h;
      std::filesystem::create_directories(dir);
      if (std::string(h) == "b") std::filesystem::create_symlink(root + "/a/runs.db", dir + "/runs.db");
      hosts_.push_back(std::make_unique<ServerProcess>(
          dir, std::string(R"("lab": {"host": "host-)") + h + R"(", "lease_ttl_s": 1, "heartbeat_s": 0.25})",
          std::string(R"([{"name": ")") + h + R"(-emu", "kind": "emulated", "pace": "realtime",
                          "model": {"preset": "taghizadeh2009"}}])"));
      addr_.push_back(hosts_.back()->Start());
      ASSERT_FALSE(addr_.back().empty()) << hosts_.back()->Log();
    }
    db_path_ = root + "/a/runs.db";
  }

  // Waits until the run is running; returns the index (0: a, 1: b) of the host executing it.
  int WaitRunning(client::Client& c, std::int64_t id) {
    const auto until = Clock::now() + std::chrono::seconds(10);
    while (Clock::now() < until) {
      auto r = c.GetRun(id);
      if (r.ok() && r->status() == v1::RUNNING && !r->host().empty()) return r->host() == "host-a" ? 0 : 1;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    ADD_FAILURE() << "run " << id << " never ran";
    return 0;
  }

  v1::Run WaitEnded(client::Client& c, std::int64_t id, double timeout_s) {
    const auto until = Clock::now() + std::chrono::duration<double>(timeout_s);
    v1::Run last;
    while (Clock::now() < until) {
      auto r = c.GetRun(id);
      if (r.ok()) last = *r;
      if (r.ok() && Ended(r->status())) return *r;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    ADD_FAILURE() << "run " << id << " did not end in " << timeout_s << " s";
    return last;
  }

  static int Count(const v1::Run& r, v1::RunStatus s) {
    int n = 0;
    for (const auto& h : r.history()) n += h.status() == s;
    return n;
  }

  std::vector<std::unique_ptr<ServerProcess>> hosts_;
  std::vector<std::string> addr_;
  std::string db_path_;
};

TEST_F(LabTest, EveryHostListsEveryHostsBenchesAndARunIsWatchedAndCancelledThroughTheOtherHost) {
  auto via_a = MakeClient(addr_[0], testing::kOperatorToken);
  auto benches = via_a.Benches();
  ASSERT_TRUE(benches.ok()) << benches.status().message();
  ASSERT_EQ(benches->benches_size(), 2);
  for (int k = 0; k < 2; ++k) {
    const auto& b = benches->benches(k);
    EXPECT_EQ(b.host(), k == 0 ? "host-a" : "host-b");
    EXPECT_EQ(b.name(), k == 0 ? "a-emu" : "b-emu");
    EXPECT_EQ(b.host_address(), addr_[k]);
    EXPECT_TRUE(b.alive());
    EXPECT_TRUE(b.paced());
    EXPECT_LT(b.heartbeat_age_s(), 1.0);
  }

  auto sub = via_a.Submit(PacedRun(4.0));
  ASSERT_TRUE(sub.ok()) << sub.status().message();
  const std::int64_t id = sub->run_ids(0);
  const int x = WaitRunning(via_a, id);
  auto other = MakeClient(addr_[1 - x], testing::kOperatorToken);
  // Benches through the other host show the run on the executing host's bench.
  auto busy = other.Benches();
  ASSERT_TRUE(busy.ok());
  EXPECT_TRUE(busy->benches(x).busy());
  EXPECT_EQ(busy->benches(x).current_run_id(), id);

  // Watched through the host that does not execute it: progress from the store moves while it runs.
  double seen = 0.0;
  const auto t0 = Clock::now();
  auto st = other.Watch(id, 10.0, 0.0, [&](const v1::RunEvent& ev) {
    if (ev.status() == v1::RUNNING) seen = std::max(seen, ev.progress());
    return seen < 0.2;
  });
  EXPECT_GE(seen, 0.2) << st.message();
  EXPECT_LT(std::chrono::duration<double>(Clock::now() - t0).count(), 3.0);

  // Cancelled through it too: the executing host sees the request in the store and stops the run.
  auto cancelled = other.Cancel(id, "lab test");
  ASSERT_TRUE(cancelled.ok()) << cancelled.status().message();
  const v1::Run r = WaitEnded(other, id, 2.0);
  EXPECT_EQ(r.status(), v1::CANCELLED);
  EXPECT_NE(r.reason().find("lab test"), std::string::npos) << r.reason();
  EXPECT_LT(r.progress(), 0.8);
  EXPECT_EQ(r.host(), x == 0 ? "host-a" : "host-b");
}

// Admission in a lab matches runs against every host's benches: a run naming host b's bench is accepted
// through host a and executes on host b; a bench no host has is still refused, naming the lab's benches.
TEST_F(LabTest, AHostAcceptsARunOnlyAnotherHostsBenchCanTake) {
  auto via_a = MakeClient(addr_[0], testing::kOperatorToken);
  v1::ExperimentSpec spec = PacedRun(0.05);
  spec.mutable_bench()->set_name("b-emu");
  auto sub = via_a.Submit(spec);
  ASSERT_TRUE(sub.ok()) << sub.status().message();
  const v1::Run r = WaitEnded(via_a, sub->run_ids(0), 10.0);
  EXPECT_EQ(r.status(), v1::DONE);
  EXPECT_EQ(r.host(), "host-b");
  EXPECT_EQ(r.bench(), "b-emu");
  spec.mutable_bench()->set_name("c-emu");
  auto refused = via_a.Submit(spec);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(refused.status().message().find("b-emu"), std::string::npos) << refused.status().message();
}

TEST_F(LabTest, ARunOfASigkilledHostFinishesOnTheOtherHostExactlyOnce) {
  auto via_a = MakeClient(addr_[0], testing::kOperatorToken);
  auto sub = via_a.Submit(PacedRun(1.5));
  ASSERT_TRUE(sub.ok()) << sub.status().message();
  const std::int64_t id = sub->run_ids(0);
  const int x = WaitRunning(via_a, id);
  hosts_[x]->Kill(SIGKILL);
  auto other = MakeClient(addr_[1 - x], testing::kViewerToken);
  const v1::Run r = WaitEnded(other, id, 10.0);
  EXPECT_EQ(r.status(), v1::DONE);
  EXPECT_EQ(r.host(), x == 0 ? "host-b" : "host-a");
  EXPECT_EQ(r.fence(), 2);
  EXPECT_EQ(Count(r, v1::DONE), 1);
  EXPECT_EQ(Count(r, v1::INTERRUPTED), 1);
  bool lapsed = false;
  for (const auto& h : r.history()) lapsed = lapsed || h.reason().find("lease lapsed") != std::string::npos;
  EXPECT_TRUE(lapsed);
  // The killed host is listed as down.
  auto benches = other.Benches();
  ASSERT_TRUE(benches.ok());
  EXPECT_FALSE(benches->benches(x).alive());
  EXPECT_TRUE(benches->benches(1 - x).alive());
}

TEST_F(LabTest, AStoppedHostLosesItsRunAndItsLateWritesAreRefused) {
  auto via_a = MakeClient(addr_[0], testing::kOperatorToken);
  auto sub = via_a.Submit(PacedRun(1.5));
  ASSERT_TRUE(sub.ok()) << sub.status().message();
  const std::int64_t id = sub->run_ids(0);
  const int x = WaitRunning(via_a, id);
  std::this_thread::sleep_for(std::chrono::milliseconds(600));  // a progress write or two
  hosts_[x]->Signal(SIGSTOP);
  auto other = MakeClient(addr_[1 - x], testing::kViewerToken);
  const std::string other_host = x == 0 ? "host-b" : "host-a";
  const auto until = Clock::now() + std::chrono::seconds(8);
  bool taken = false;
  while (!taken && Clock::now() < until) {
    auto r = other.GetRun(id);
    taken = r.ok() && r->host() == other_host;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  hosts_[x]->Signal(SIGCONT);
  ASSERT_TRUE(taken) << "the other host never took the run";
  const v1::Run r = WaitEnded(other, id, 10.0);
  EXPECT_EQ(r.status(), v1::DONE);
  EXPECT_EQ(r.host(), other_host);
  EXPECT_EQ(Count(r, v1::DONE), 1);
  // The stopped host, continued, wrote for its attempt (progress, trace or result): refused and recorded.
  auto store = db::OpenSqliteStore(db_path_);
  ASSERT_TRUE(store.ok()) << store.status().message();
  std::int64_t total = 0;
  std::vector<db::StaleWrite> stale;
  const auto wait_stale = Clock::now() + std::chrono::seconds(5);
  while (Clock::now() < wait_stale) {
    auto s = (*store)->StaleWrites(100, &total);
    ASSERT_TRUE(s.ok());
    stale = *s;
    if (total > 0) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  ASSERT_GE(total, 1);
  EXPECT_EQ(stale[0].run_id, id);
  EXPECT_EQ(stale[0].fence, 1);
  EXPECT_EQ(stale[0].current_fence, 2);
  // Its trace is the surviving attempt's alone: whole, from 0 to the end.
  auto trace = (*store)->ReadTrace(id);
  ASSERT_TRUE(trace.ok()) << trace.status().message();
  ASSERT_FALSE(trace->empty());
  EXPECT_EQ((*trace)[0].t0_s, 0.0);
}

// A run executing on a host this server does not know in-process ("ghost", driven from the test through the
// store as a host would): a watch through the server follows its progress and the samples of its stored chunks.
TEST(LabWatch, ARunOnAnotherHostIsFollowedFromTheStore) {
  const std::string dir = ::testing::TempDir() + "/vb-lab-watch-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  ServerProcess server(dir, R"("lab": {"host": "host-a", "lease_ttl_s": 5})");
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto store = db::OpenSqliteStore(server.db_path());
  ASSERT_TRUE(store.ok()) << store.status().message();
  db::RunRecord rec;
  rec.key = NamedRun("far");
  rec.bench_kind = "ghost-kind";  // no bench of host-a can take it
  rec.spec_json = "{}";
  std::vector<std::int64_t> ids;
  ASSERT_TRUE((*store)->SubmitBatch("ghost-user", "far", "{}", {rec}, &ids).ok());
  db::ClaimRequest claim = db::BenchClaim("ghost-kind", "ghost-bench");
  claim.host = "ghost";
  claim.lease_ttl_s = 60;
  auto claimed = (*store)->ClaimNext(claim);
  ASSERT_TRUE(claimed.ok() && claimed->has_value());
  const db::Lease lease = db::LeaseOf(**claimed);
  db::TraceChunk c;
  c.sample_period_s = 1e-3;
  c.samples = 100;
  c.channels = {"t_s", "gate", "i_A", "x_m", "ref"};
  for (int ch = 0; ch < 5; ++ch)
    for (int k = 0; k < c.samples; ++k) c.data.push_back(ch == 0 ? k * 1e-3 : ch == 1 ? k % 2 : ch == 2 ? 0.01 * k : 0.0);
  ASSERT_TRUE((*store)->AppendTraceChunk(lease, c).ok());
  ASSERT_TRUE((*store)->SetProgress(lease, 0.5).ok());

  auto viewer = MakeClient(addr, testing::kViewerToken);
  double progress = 0.0;
  std::vector<double> currents;
  auto st = viewer.Watch(ids[0], 5.0, 1000.0, [&](const v1::RunEvent& ev) {
    progress = ev.progress();
    for (const auto& s : ev.samples()) currents.push_back(s.i_a());
    return currents.size() < 100;
  });
  EXPECT_EQ(progress, 0.5);
  ASSERT_EQ(currents.size(), 100u) << st.message();
  EXPECT_DOUBLE_EQ(currents[0], 0.0);
  EXPECT_DOUBLE_EQ(currents[99], 0.99);

  // It ends on its host; the watch through host-a says so.
  ASSERT_TRUE((*store)->Finish(lease, db::RunStatus::kDone, "", {}).ok());
  v1::RunStatus last = v1::RUN_STATUS_UNSPECIFIED;
  st = viewer.Watch(ids[0], 5.0, 0.0, [&](const v1::RunEvent& ev) {
    last = ev.status();
    return true;
  });
  EXPECT_TRUE(st.ok()) << st.message();
  EXPECT_EQ(last, v1::DONE);
  auto shown = viewer.GetRun(ids[0]);
  ASSERT_TRUE(shown.ok());
  EXPECT_EQ(shown->host(), "ghost");
}

// Nights run once per lab (docs/lab.md, "Nights"): two hosts with the same nights block both try tonight's night
// at start; one claims and runs it, the other skips it; one regression result, one batch.
TEST(LabNights, TwoHostsRunTonightsNightOnce) {
  const std::string suites = std::string(VB_SOURCE_DIR) + "/examples/suites/";
  const std::string nights = R"("nights": {"cron": "0 2 * * *", "suite_file": ")" + suites +
                             R"(ci.json", "baseline_file": ")" + suites + R"(ci-baseline.json"})";
  const std::string root = ::testing::TempDir() + "/vb-lab-nights-" + std::to_string(::getpid());
  std::filesystem::remove_all(root);
  std::vector<std::unique_ptr<ServerProcess>> hosts;
  std::vector<std::string> addr;
  for (const char* h : {"a", "b"}) {
    const std::string dir = root + "/" + h;
    std::filesystem::create_directories(dir);
    if (std::string(h) == "b") std::filesystem::create_symlink(root + "/a/runs.db", dir + "/runs.db");
    hosts.push_back(std::make_unique<ServerProcess>(
        dir, nights + R"(, "lab": {"host": "host-)" + h + R"(", "lease_ttl_s": 2})"));
    hosts.back()->AddArg("--run-night-now");
    addr.push_back(hosts.back()->Start());
    ASSERT_FALSE(addr.back().empty()) << hosts.back()->Log();
  }
  auto viewer = MakeClient(addr[1], testing::kViewerToken);
  const auto until = Clock::now() + std::chrono::seconds(60);
  int listed = 0;
  while (Clock::now() < until && listed == 0) {
    auto n = viewer.ListNights(10);
    ASSERT_TRUE(n.ok()) << n.status().message();
    listed = n->nights_size();
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  ASSERT_EQ(listed, 1) << hosts[0]->Log() << hosts[1]->Log();
  std::this_thread::sleep_for(std::chrono::seconds(1));  // the loser would have stored its night by now
  auto n = viewer.ListNights(10);
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(n->nights_size(), 1);
  const std::string logs = hosts[0]->Log() + hosts[1]->Log();
  auto count = [&](const std::string& what) {
    int k = 0;
    for (auto at = logs.find(what); at != std::string::npos; at = logs.find(what, at + 1)) ++k;
    return k;
  };
  EXPECT_EQ(count("claimed by this host"), 1) << logs;
  EXPECT_EQ(count("another host of the lab runs it"), 1) << logs;
  v1::ListRunsRequest req;
  req.set_tag("night");
  auto runs = viewer.ListRuns(req);
  ASSERT_TRUE(runs.ok());
  EXPECT_EQ(runs->runs_size(), 9);  // one batch of the ci suite, not two
}

// A lab's night checks every live host's benches (docs/track.md, "In a lab"): host-b has a checked bench and no
// nights; host-a claims tonight and queues b1's health check beside a1's; b1's runs execute on host-b, and the
// night identifies both (GetBenchHealth lists both benches, each with tonight's check).
TEST(LabNights, TheClaimingHostChecksEveryLiveHostsBenches) {
  const std::string suites = std::string(VB_SOURCE_DIR) + "/examples/suites/";
  const std::string nights = R"("nights": {"cron": "0 2 * * *", "suite_file": ")" + suites +
                             R"(ci.json", "baseline_file": ")" + suites + R"(ci-baseline.json"}, )";
  const std::string health =
      R"("health": {"supply_V": [24], "supply_pressure_Pa": [100000, 400000]}, "current_noise_A": 0.002)";
  const std::string root = ::testing::TempDir() + "/vb-lab-health-" + std::to_string(::getpid());
  std::filesystem::remove_all(root);
  std::filesystem::create_directories(root + "/a");
  std::filesystem::create_directories(root + "/b");
  std::filesystem::create_symlink(root + "/a/runs.db", root + "/b/runs.db");
  auto bench = [&](const char* name) {
    return std::string(R"([{"name": ")") + name + R"(", "kind": "emulated", "model": {"preset": "taghizadeh2009"}, )" +
           health + "}]";
  };
  // host-b first, so that it is registered (with its benches' health blocks) when host-a claims the night.
  ServerProcess b(root + "/b", R"("lab": {"host": "host-b", "lease_ttl_s": 2})", bench("b1"));
  ASSERT_FALSE(b.Start().empty()) << b.Log();
  ServerProcess a(root + "/a", nights + R"("lab": {"host": "host-a", "lease_ttl_s": 2})", bench("a1"));
  a.AddArg("--run-night-now");
  const std::string addr = a.Start();
  ASSERT_FALSE(addr.empty()) << a.Log();
  auto viewer = MakeClient(addr, testing::kViewerToken);
  const auto until = Clock::now() + std::chrono::seconds(180);
  int listed = 0;
  while (Clock::now() < until && listed == 0) {
    auto n = viewer.ListNights(10);
    ASSERT_TRUE(n.ok()) << n.status().message();
    listed = n->nights_size();
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
  }
  ASSERT_EQ(listed, 1) << a.Log() << b.Log();
  EXPECT_NE(a.Log().find("health check of b1: batch"), std::string::npos) << a.Log();
  v1::ListRunsRequest req;
  req.set_tag("health:b1");
  auto runs = viewer.ListRuns(req);
  ASSERT_TRUE(runs.ok()) << runs.status().message();
  ASSERT_EQ(runs->runs_size(), 3);  // the two switch-ons and the hold
  for (const auto& r : runs->runs()) {
    EXPECT_EQ(r.status(), v1::DONE) << r.reason();
    EXPECT_EQ(r.host(), "host-b");
    EXPECT_EQ(r.bench(), "b1");
  }
  auto served = viewer.GetBenchHealth("");
  ASSERT_TRUE(served.ok()) << served.status().message();
  std::vector<std::string> checked;
  for (const auto& bh : served->benches()) checked.push_back(bh.bench());
  EXPECT_EQ(checked, (std::vector<std::string>{"a1", "b1"})) << served->DebugString().substr(0, 2000);
  for (const auto& bh : served->benches()) EXPECT_EQ(bh.nights_size(), 1) << bh.bench();
}

std::string ErrorOf(const v1::ServerConfig& c) {
  auto s = server::SettingsFromConfig(c, "");
  return s.ok() ? std::string("(accepted)") : s.status().message();
}

TEST(LabConfig, DefaultsAndErrorsNamingTheField) {
  auto none = server::SettingsFromConfig(testing::MinimalConfig(), "");
  ASSERT_TRUE(none.ok()) << none.status().message();
  EXPECT_FALSE(none->lab.enabled);
  EXPECT_TRUE(none->nights.lab_host.empty());

  auto c = testing::MinimalConfig();
  c.mutable_lab();  // an empty block: a lab host with every default
  auto defaults = server::SettingsFromConfig(c, "");
  ASSERT_TRUE(defaults.ok()) << defaults.status().message();
  EXPECT_TRUE(defaults->lab.enabled);
  char hostname[256] = {};
  ASSERT_EQ(gethostname(hostname, sizeof hostname - 1), 0);
  EXPECT_EQ(defaults->lab.host, hostname);
  EXPECT_EQ(defaults->lab.lease_ttl_s, 10.0);
  EXPECT_DOUBLE_EQ(defaults->lab.heartbeat_s, 10.0 / 3.0);
  EXPECT_EQ(defaults->lab.aging_s, 60.0);

  c.mutable_lab()->set_host("rig-7");
  c.mutable_lab()->set_lease_ttl_s(4);
  c.mutable_lab()->set_aging_s(-1);
  auto set = server::SettingsFromConfig(c, "");
  ASSERT_TRUE(set.ok()) << set.status().message();
  EXPECT_EQ(set->lab.host, "rig-7");
  EXPECT_DOUBLE_EQ(set->lab.heartbeat_s, 4.0 / 3.0);
  EXPECT_EQ(set->lab.aging_s, 0.0);  // < 0: no aging

  auto slow = c;
  slow.mutable_lab()->set_heartbeat_s(3);
  EXPECT_EQ(ErrorOf(slow).rfind("lab.heartbeat_s: ", 0), 0u) << ErrorOf(slow);
  auto negative = c;
  negative.mutable_lab()->set_lease_ttl_s(-1);
  EXPECT_EQ(ErrorOf(negative).rfind("lab.lease_ttl_s: ", 0), 0u) << ErrorOf(negative);

  auto paced = testing::MinimalConfig();
  paced.mutable_benches(0)->set_pace("realtime");
  auto p = server::SettingsFromConfig(paced, "");
  ASSERT_TRUE(p.ok()) << p.status().message();
  EXPECT_TRUE(p->benches[0].paced);
  paced.mutable_benches(0)->set_pace("fast");
  EXPECT_EQ(ErrorOf(paced).rfind("benches[0].pace: ", 0), 0u) << ErrorOf(paced);
}

}  // namespace
}  // namespace vb
