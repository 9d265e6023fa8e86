// The local service (service/local_service.h): the BenchService over a store and the local emulator in this
// process, reached through its in-process channel with client::Client, as benchctl --local reaches it.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <thread>

#include "client/client.h"
#include "experiment/spec.h"
#include "runs/build_identity.h"
#include "service/local_service.h"

namespace vb {
namespace {

namespace v1 = valvebench::v1;

std::string TempDir(const std::string& name) {
  const std::string d = ::testing::TempDir() + "/vb-local-" + name + "-" + std::to_string(::getpid());
  std::filesystem::remove_all(d);
  return d;
}

client::Client ClientOf(server::LocalService& s) {
  client::ClientOptions o;
  o.address = s.Where();
  o.token = s.token();
  o.deadline_s = 60.0;
  return client::Client(s.InProcessChannel(), o);
}

v1::ExperimentSpec Spec(const std::string& json) {
  auto s = experiment::ParseSpecJson(json);
  EXPECT_TRUE(s.ok()) << s.status().message();
  return *s;
}

const char* kShortSpec = R"({"name": "short", "duration_s": 0.05,
  "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 100, "duty": 0.5}]}}})";

void WaitEnded(client::Client& c, std::int64_t id) {
  auto st = c.Watch(id, 60.0, 0.0, [](const v1::RunEvent& ev) {
    return ev.status() == v1::QUEUED || ev.status() == v1::RUNNING;
  });
  ASSERT_TRUE(st.ok()) << st.message();
}

// A run submitted through the channel is executed by the service's worker and is then what ListRuns, GetRun,
// GetQueue and GetTrace of the same service say; with keep_traces its whole trace is kept too.
TEST(LocalService, RunsGoThroughTheServiceAndAreVisibleToItsViews) {
  const std::string dir = TempDir("views");
  server::LocalServiceOptions o;
  o.store = dir + "/sub/runs.db";  // its directory is created
  o.keep_traces = true;
  auto s = server::LocalService::Start(o);
  ASSERT_TRUE(s.ok()) << s.status().message();
  auto c = ClientOf(**s);
  auto sub = c.Submit(Spec(kShortSpec));
  ASSERT_TRUE(sub.ok()) << sub.status().message();
  ASSERT_EQ(sub->run_ids_size(), 1);
  const std::int64_t id = sub->run_ids(0);
  WaitEnded(c, id);
  auto run = c.GetRun(id);
  ASSERT_TRUE(run.ok()) << run.status().message();
  EXPECT_EQ(run->status(), v1::DONE) << run->reason();
  EXPECT_EQ(run->bench(), "local-emulator");
  v1::ListRunsRequest req;
  auto listed = c.ListRuns(req);
  ASSERT_TRUE(listed.ok());
  ASSERT_EQ(listed->runs_size(), 1);
  EXPECT_EQ(listed->runs(0).id(), id);
  auto q = c.GetQueue();
  ASSERT_TRUE(q.ok()) << q.status().message();
  EXPECT_EQ(q->running_size(), 0);
  EXPECT_EQ(q->queued_size(), 0);
  ASSERT_EQ(q->benches_size(), 1);
  EXPECT_EQ(q->benches(0).name(), "local-emulator");
  EXPECT_EQ(q->live_benches(), 1);
  auto trace = c.GetTrace(id);
  ASSERT_TRUE(trace.ok()) << trace.status().message();
  EXPECT_GT(trace->samples(), 100u);
  auto kept = (*s)->KeptTrace(id);
  ASSERT_TRUE(kept.has_value());
  EXPECT_GT(kept->size(), 100u);
  EXPECT_FALSE((*s)->KeptTrace(id + 1).has_value());
  // What executing it measured is on the run itself; a run not paced has no loop statistics.
  auto got = c.GetRun(id);
  ASSERT_TRUE(got.ok()) << got.status().message();
  ASSERT_TRUE(got->has_execution());
  EXPECT_EQ(static_cast<std::size_t>(got->execution().samples()), kept->size());
  EXPECT_GT(got->execution().wall_s(), 0.0);
  EXPECT_FALSE(got->execution().has_loop());
  // The build that executed it: this test's executable, named by its SHA-256 as sha256sum computes it.
  EXPECT_EQ(got->execution().build(), runs::ThisBuild());
  EXPECT_EQ(got->execution().build().rfind("valvebench ", 0), 0u) << got->execution().build();
  {
    // By pid: popen's shell would read its own /proc/self/exe.
    const std::string cmd = "sha256sum /proc/" + std::to_string(::getpid()) + "/exe";
    std::unique_ptr<FILE, int (*)(FILE*)> p(popen(cmd.c_str(), "r"), &pclose);
    ASSERT_NE(p, nullptr);
    std::string sum(32, '\0');
    sum.resize(std::fread(sum.data(), 1, sum.size(), p.get()));
    EXPECT_EQ(runs::BuildDigest(got->execution().build()), "sha256:" + sum);
  }
  EXPECT_NE((*s)->Where().find("local store "), std::string::npos);
  EXPECT_TRUE((*s)->keeps_runs());
  s->reset();
  EXPECT_TRUE(std::filesystem::exists(dir + "/sub/runs.db")) << "a named store outlives the service";
}

// A service that does not execute (benchctl show/queue/cancel --local) leaves queued runs queued, and GetQueue
// gives them positions in claim order; a service that executes on the same store first cancels what an
// interrupted invocation left queued, naming why.
TEST(LocalService, AReadingServiceQueuesAndAnExecutingOneCancelsLeftOvers) {
  const std::string dir = TempDir("leftovers");
  std::filesystem::create_directories(dir);
  std::vector<std::int64_t> ids;
  {
    server::LocalServiceOptions o;
    o.store = dir + "/runs.db";
    o.execute = false;
    auto s = server::LocalService::Start(o);
    ASSERT_TRUE(s.ok()) << s.status().message();
    auto c = ClientOf(**s);
    for (int k = 0; k < 3; ++k) {
      auto sub = c.Submit(Spec(kShortSpec));
      ASSERT_TRUE(sub.ok()) << sub.status().message();
      ids.push_back(sub->run_ids(0));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    auto q = c.GetQueue();
    ASSERT_TRUE(q.ok()) << q.status().message();
    ASSERT_EQ(q->queued_size(), 3);
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(q->queued(k).run().id(), ids[static_cast<size_t>(k)]);
      EXPECT_EQ(q->queued(k).position(), k + 1);
      EXPECT_GT(q->queued(k).eta_s(), 0.0);
    }
    EXPECT_LT(q->queued(0).eta_s(), q->queued(2).eta_s()) << "a later place ends later";
  }
  server::LocalServiceOptions o;
  o.store = dir + "/runs.db";
  auto s = server::LocalService::Start(o);
  ASSERT_TRUE(s.ok()) << s.status().message();
  auto c = ClientOf(**s);
  for (auto id : ids) {
    auto r = c.GetRun(id);
    ASSERT_TRUE(r.ok());
    EXPECT_EQ(r->status(), v1::CANCELLED);
    EXPECT_NE(r->reason().find("left over from an interrupted local run"), std::string::npos) << r->reason();
  }
}

// A paced run of 20 s: long enough to be cancelled or stopped while it executes.
const char* kLongPacedSpec = R"({"name": "long", "duration_s": 20, "recording": {"rate_Hz": 1000},
  "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 100, "duty": 0.5}]}}})";

std::int64_t SubmitAndWaitRunning(client::Client& c, const char* spec) {
  auto sub = c.Submit(Spec(spec));
  EXPECT_TRUE(sub.ok()) << sub.status().message();
  if (!sub.ok()) return 0;
  const std::int64_t id = sub->run_ids(0);
  for (int k = 0; k < 200; ++k) {
    auto r = c.GetRun(id);
    if (r.ok() && r->status() == v1::RUNNING) return id;
    std::this_thread::sleep_for(std::chrono::milliseconds(25));
  }
  ADD_FAILURE() << "run " << id << " did not start";
  return id;
}

// The host's relay (runs::WatchRuns, service/host.h): a cancel asked of another service on the same store (benchctl
// cancel in another shell) reaches the run executing in this one through the store, and it ends cancelled.
TEST(LocalService, ACancelThroughTheStoreStopsARunExecutingInAnotherService) {
  const std::string dir = TempDir("relay");
  std::filesystem::create_directories(dir);
  server::LocalServiceOptions o;
  o.store = dir + "/runs.db";
  o.realtime = true;
  auto executing = server::LocalService::Start(o);
  ASSERT_TRUE(executing.ok()) << executing.status().message();
  auto c = ClientOf(**executing);
  const std::int64_t id = SubmitAndWaitRunning(c, kLongPacedSpec);
  server::LocalServiceOptions r = o;
  r.execute = false;
  auto reading = server::LocalService::Start(r);
  ASSERT_TRUE(reading.ok()) << reading.status().message();
  auto other = ClientOf(**reading);
  const auto asked = std::chrono::steady_clock::now();
  auto cancelled = other.Cancel(id, "from another shell");
  ASSERT_TRUE(cancelled.ok()) << cancelled.status().message();
  WaitEnded(c, id);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - asked).count(), 5.0);
  auto run = c.GetRun(id);
  ASSERT_TRUE(run.ok());
  EXPECT_EQ(run->status(), v1::CANCELLED) << run->reason();
}

// A local service that ends while its run executes records the run cancelled (runs::Worker::StopCancelling):
// nobody would resume it, unlike a server's, which leaves it running for the next start's recovery.
TEST(LocalService, ARunExecutingWhenTheServiceEndsIsRecordedCancelled) {
  const std::string dir = TempDir("ends");
  std::filesystem::create_directories(dir);
  server::LocalServiceOptions o;
  o.store = dir + "/runs.db";
  o.realtime = true;
  std::int64_t id = 0;
  {
    auto s = server::LocalService::Start(o);
    ASSERT_TRUE(s.ok()) << s.status().message();
    auto c = ClientOf(**s);
    id = SubmitAndWaitRunning(c, kLongPacedSpec);
  }
  o.execute = false;
  auto s = server::LocalService::Start(o);
  ASSERT_TRUE(s.ok()) << s.status().message();
  auto c = ClientOf(**s);
  auto run = c.GetRun(id);
  ASSERT_TRUE(run.ok()) << run.status().message();
  EXPECT_EQ(run->status(), v1::CANCELLED) << run->reason();
}

// --no-store: a private store that works like any other while the service lives and is gone after it.
TEST(LocalService, NoStoreIsAPrivateStoreRemovedWithTheService) {
  std::filesystem::path private_dir;
  {
    auto s = server::LocalService::Start({});
    ASSERT_TRUE(s.ok()) << s.status().message();
    EXPECT_EQ((*s)->Where(), "in-memory store (--no-store)");
    EXPECT_FALSE((*s)->keeps_runs());
    auto c = ClientOf(**s);
    auto sub = c.Submit(Spec(kShortSpec));
    ASSERT_TRUE(sub.ok()) << sub.status().message();
    WaitEnded(c, sub->run_ids(0));
    auto cmp = c.Compare(sub->batch_id(), {});
    ASSERT_TRUE(cmp.ok()) << cmp.status().message();
    EXPECT_EQ(cmp->rows_size(), 1);
    const std::filesystem::path file = (*s)->store_path();
    ASSERT_TRUE(std::filesystem::exists(file)) << file;
    private_dir = file.parent_path();
    EXPECT_EQ(private_dir.parent_path(), std::filesystem::temp_directory_path());
  }
  EXPECT_FALSE(std::filesystem::exists(private_dir)) << private_dir;
}

// Measured runs can be imported into a local store now: the service has ImportRuns.
TEST(LocalService, ImportsMeasuredRuns) {
  auto s = server::LocalService::Start({});
  ASSERT_TRUE(s.ok()) << s.status().message();
  auto c = ClientOf(**s);
  v1::ImportRunsRequest req;
  req.set_dataset("bench7");
  auto* r = req.add_runs();
  r->set_id("a");
  r->set_supply_v(24.0);
  r->set_sample_period_s(1e-4);
  for (int k = 0; k < 50; ++k) {
    r->add_gate(k >= 10 ? 1 : 0);
    r->add_i_a(k >= 10 ? 0.01 * (k - 10) : 0.0);
  }
  auto ok = c.ImportRuns(req);
  ASSERT_TRUE(ok.ok()) << ok.status().message();
  ASSERT_EQ(ok->run_ids_size(), 1);
  auto run = c.GetRun(ok->run_ids(0));
  ASSERT_TRUE(run.ok()) << run.status().message();
  EXPECT_EQ(run->status(), v1::DONE);
  auto trace = c.GetTrace(ok->run_ids(0));
  ASSERT_TRUE(trace.ok()) << trace.status().message();
  EXPECT_EQ(trace->samples(), 50u);
}

// A store that cannot be opened: the error names it.
TEST(LocalService, AStoreThatCannotBeOpenedIsNamed) {
  server::LocalServiceOptions o;
  o.store = "/proc/self/no-such-dir/runs.db";
  auto s = server::LocalService::Start(o);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("local store /proc/self/no-such-dir/runs.db"), std::string::npos)
      << s.status().message();
}

}  // namespace
}  // namespace vb
