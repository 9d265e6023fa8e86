// GetQueue (proto/valvebench/v1/api.proto) on the real valvebench-server over loopback: positions in claim
// order and ETAs replaying the claims on the live benches, and benchctl queue showing the same view.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <thread>

#include "../common/run_command.h"
#include "client/client.h"
#include "experiment/spec.h"
#include "server_process.h"

namespace vb {
namespace {

namespace v1 = valvebench::v1;
using testing::ServerProcess;

std::string QueueTempDir(const std::string& name) {
  const std::string d = ::testing::TempDir() + "/vb-queue-" + name + "-" + std::to_string(::getpid());
  std::filesystem::remove_all(d);
  return d;
}

// Two paced benches busy with 20 s runs and four more queued, one with a higher priority: the running ones have
// position 0 and an ETA of their wall time left; the queued ones are in claim order (priority, then age),
// positions 1..4, each ETA no earlier than the one before, as common/queue_estimate.h computes them.
TEST(Queue, GetQueueGivesPositionsAndEtasInClaimOrder) {
  ServerProcess server(QueueTempDir("positions"), "",
                       R"([{"name": "emu-a", "kind": "emulated", "model": {"preset": "taghizadeh2009"}, "pace": "realtime"},
                           {"name": "emu-b", "kind": "emulated", "model": {"preset": "taghizadeh2009"}, "pace": "realtime"}])");
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  client::ClientOptions o;
  o.address = addr;
  o.token = testing::kOperatorToken;
  client::Client c(o);
  auto spec = [](int priority) {
    auto s = experiment::ParseSpecJson(R"({"name": "long", "duration_s": 20,
      "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 100, "duty": 0.5}]}}})");
    EXPECT_TRUE(s.ok()) << s.status().message();
    s->set_priority(priority);
    return *s;
  };
  std::vector<std::int64_t> ids;
  for (int priority : {0, 0, 0, 0, 5, 0}) {
    auto sub = c.Submit(spec(priority));
    ASSERT_TRUE(sub.ok()) << sub.status().message();
    ids.push_back(sub->run_ids(0));
  }
  v1::GetQueueResponse q;
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (std::chrono::steady_clock::now() < until) {
    auto got = c.GetQueue();
    ASSERT_TRUE(got.ok()) << got.status().message();
    q = *got;
    if (q.running_size() == 2 && q.running(0).eta_s() > 0 && q.running(1).eta_s() > 0) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_EQ(q.running_size(), 2) << q.DebugString();
  EXPECT_EQ(q.live_benches(), 2);
  EXPECT_EQ(q.benches_size(), 2);
  EXPECT_GT(q.at_unix_s(), 0.0);
  double longest_running_s = 0.0;
  for (const auto& r : q.running()) {
    EXPECT_EQ(r.position(), 0);
    EXPECT_EQ(r.run().status(), v1::RUNNING);
    EXPECT_GT(r.eta_s(), 5.0);  // wall time left, extrapolated from the progress so far (20 s runs just begun)
    longest_running_s = std::max(longest_running_s, r.eta_s());
  }
  ASSERT_EQ(q.queued_size(), 4) << q.DebugString();
  // Claim order: the priority-5 run first, then the others by age.
  EXPECT_EQ(q.queued(0).run().id(), ids[4]);
  EXPECT_EQ(q.queued(1).run().id(), ids[2]);
  EXPECT_EQ(q.queued(2).run().id(), ids[3]);
  EXPECT_EQ(q.queued(3).run().id(), ids[5]);
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(q.queued(k).position(), k + 1);
    EXPECT_EQ(q.queued(k).run().status(), v1::QUEUED);
    if (k > 0) {
      EXPECT_GE(q.queued(k).eta_s(), q.queued(k - 1).eta_s());
    }
  }
  // ETA of a queued run: the claims replayed (issue 37; before, the bench time was spread evenly over the live
  // benches, which gave the first queued run 30 s although no bench is free before ~20 s): each bench is free
  // when its 20 s run ends, then takes the next run, so the first two end at ~40 s and the last two at ~60 s.
  EXPECT_GT(longest_running_s, 0.0);
  EXPECT_GT(q.queued(0).eta_s(), 30.0);
  EXPECT_LT(q.queued(0).eta_s(), 41.0);
  EXPECT_NEAR(q.queued(1).eta_s(), q.queued(0).eta_s(), 2.0);
  EXPECT_GT(q.queued(3).eta_s(), 50.0);
  EXPECT_LT(q.queued(3).eta_s(), 61.0);

  // benchctl queue shows the same view: positions and the live benches from GetQueue.
  auto shown = testing::RunCommand(std::string(VB_BENCHCTL) + " queue --json --server " + addr + " --token " +
                                   testing::kViewerToken);
  ASSERT_EQ(shown.exit_code, 0) << shown.out;
  const auto j = nlohmann::json::parse(shown.out);
  ASSERT_EQ(j["runs"].size(), 6u) << shown.out;
  EXPECT_EQ(j["live_benches"], 2);
  EXPECT_EQ(j["runs"][2]["id"], ids[4]);
  EXPECT_EQ(j["runs"][2]["position"], 1);
  EXPECT_EQ(j["runs"][5]["position"], 4);
  // Cut by --limit: says how many more.
  auto cut = testing::RunCommand(std::string(VB_BENCHCTL) + " queue --limit 3 --server " + addr + " --token " +
                                 testing::kViewerToken);
  ASSERT_EQ(cut.exit_code, 0) << cut.out;
  EXPECT_NE(cut.out.find("(3 more; --limit)"), std::string::npos) << cut.out;

  auto admin = client::ClientOptions(o);
  admin.token = testing::kAdminToken;
  client::Client a(admin);
  for (auto id : ids) (void)a.Cancel(id, "test over");
}

// GetQueue needs a token like every call.
TEST(Queue, GetQueueNeedsAToken) {
  ServerProcess server(QueueTempDir("auth"));
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  client::ClientOptions o;
  o.address = addr;
  client::Client c(o);
  auto q = c.GetQueue();
  ASSERT_FALSE(q.ok());
  EXPECT_NE(q.status().message().find("not authenticated"), std::string::npos) << q.status().message();
}

}  // namespace
}  // namespace vb
