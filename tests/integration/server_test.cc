// The real valvebench-server on a loopback port with a temporary database, driven through the C++ client.
#include <gtest/gtest.h>

#include <filesystem>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <set>
#include <thread>

#include "client/client.h"
#include "common/failed_attempts.h"
#include "experiment/runner.h"
#include "experiment/spec.h"
#include "server_process.h"

namespace vb {
namespace {

namespace v1 = valvebench::v1;
using testing::ServerProcess;

std::string TempDir(const std::string& name) {
  const std::string d = ::testing::TempDir() + "/vb-it-" + name + "-" + std::to_string(::getpid());
  std::filesystem::remove_all(d);
  return d;
}

client::Client MakeClient(const std::string& address, const char* token) {
  client::ClientOptions o;
  o.address = address;
  o.token = token == nullptr ? "" : token;
  o.deadline_s = 20.0;
  return client::Client(o);
}

v1::ExperimentSpec Spec(const std::string& json) {
  auto s = experiment::ParseSpecJson(json);
  EXPECT_TRUE(s.ok()) << s.status().message();
  return *s;
}

// A short open-loop run; paced runs take their duration in wall time, so the queue builds up.
v1::ExperimentSpec ShortRun(const std::string& name, double duration_s, bool paced, int priority = 0) {
  auto s = Spec(R"({"name": ")" + name + R"(", "duration_s": )" + std::to_string(duration_s) +
                R"(, "conditions": {"supply_V": 24, "supply_pressure_Pa": 400000},
                 "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 100, "duty": 0.5}]}},
                 "recording": {"rate_Hz": 10000}})");
  s.set_realtime(paced);
  s.set_priority(priority);
  return s;
}

bool Ended(v1::RunStatus s) { return s == v1::DONE || s == v1::FAILED || s == v1::CANCELLED; }

// Waits until every run has ended; returns them.
std::vector<v1::Run> WaitAll(client::Client& c, const std::vector<std::int64_t>& ids, double timeout_s) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  std::vector<v1::Run> out;
  while (std::chrono::steady_clock::now() < until) {
    out.clear();
    bool all = true;
    for (auto id : ids) {
      auto r = c.GetRun(id);
      if (!r.ok()) return {};
      all = all && Ended(r->status());
      out.push_back(*r);
    }
    if (all) return out;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return out;
}

// Issue 34: a token is guessed at most FailedAttempts::kMax times per address in its window, over gRPC as over the
// web; then the address is refused whatever it sends, a good token too, and the answer says for how long.
TEST(Server, FailedAuthenticationsAreLimitedPerAddress) {
  ServerProcess server(TempDir("guess"), "");
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto viewer = MakeClient(addr, testing::kViewerToken);
  ASSERT_TRUE(viewer.Benches().ok());
  auto anonymous = MakeClient(addr, nullptr);
  for (int k = 0; k < 12; ++k) EXPECT_FALSE(anonymous.Benches().ok());  // no token: not a guess, not counted
  ASSERT_TRUE(viewer.Benches().ok());
  for (int k = 0; k < FailedAttempts::kMax; ++k) {
    auto guess = MakeClient(addr, ("guess-" + std::to_string(k)).c_str());
    auto st = guess.Benches();
    ASSERT_FALSE(st.ok());
    EXPECT_NE(st.status().message().find("not authenticated"), std::string::npos) << k << ": " << st.status().message();
  }
  auto after = viewer.Benches();
  ASSERT_FALSE(after.ok());
  EXPECT_EQ(after.status().code(), StatusCode::kResourceExhausted) << after.status().message();
  EXPECT_NE(after.status().message().find("too many failed authentications from 127.0.0.1"), std::string::npos)
      << after.status().message();
  EXPECT_NE(server.Log().find("failed authentication from 127.0.0.1"), std::string::npos);
}

TEST(Server, AuthenticationRolesAndErrorCodes) {
  ServerProcess server(TempDir("auth"), R"("limits": {"max_duration_s": 5})");
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();

  auto anonymous = MakeClient(addr, nullptr);
  auto st = anonymous.Benches();
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.status().message().find("not authenticated"), std::string::npos) << st.status().message();
  auto wrong = MakeClient(addr, "not-a-token");
  EXPECT_FALSE(wrong.Benches().ok());

  auto viewer = MakeClient(addr, testing::kViewerToken);
  auto benches = viewer.Benches();
  ASSERT_TRUE(benches.ok()) << benches.status().message();
  EXPECT_EQ(benches->benches_size(), 2);
  auto denied = viewer.Submit(ShortRun("x", 0.01, false));
  ASSERT_FALSE(denied.ok());
  EXPECT_NE(denied.status().message().find("permission denied"), std::string::npos) << denied.status().message();

  auto olga = MakeClient(addr, testing::kOperatorToken);
  auto bad = olga.Submit(Spec(R"({"duration_s": 0.1, "conditions": {"supply_V": -2},
      "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 50, "duty": 0.5}]}}})"));
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find("conditions.supply_V"), std::string::npos) << bad.status().message();

  auto no_bench = olga.Submit(Spec(R"({"duration_s": 0.1, "bench": {"model": {"preset": "lunge2013"}},
      "conditions": {"supply_V": 230}, "reference": {"constant": {"value": 0.001}},
      "controller": {"sliding_mode_position": {}}})"));
  ASSERT_FALSE(no_bench.ok());
  EXPECT_EQ(no_bench.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(no_bench.status().message().find("emulated:lunge2013"), std::string::npos) << no_bench.status().message();

  auto too_long = olga.Submit(ShortRun("long", 10.0, false));
  ASSERT_FALSE(too_long.ok());
  EXPECT_EQ(too_long.status().code(), StatusCode::kResourceExhausted);
  EXPECT_NE(too_long.status().message().find("duration_s"), std::string::npos);

  auto missing = viewer.GetRun(424242);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);

  // Operators cancel only their own runs; admins anyone's.
  auto mine = olga.Submit(ShortRun("mine", 2.0, true));
  ASSERT_TRUE(mine.ok()) << mine.status().message();
  auto oscar = MakeClient(addr, testing::kOperator2Token);
  auto other = oscar.Cancel(mine->run_ids(0));
  ASSERT_FALSE(other.ok());
  EXPECT_NE(other.status().message().find("only their own"), std::string::npos) << other.status().message();
  auto admin = MakeClient(addr, testing::kAdminToken);
  auto cancelled = admin.Cancel(mine->run_ids(0), "test");
  ASSERT_TRUE(cancelled.ok()) << cancelled.status().message();
  EXPECT_EQ(cancelled->status(), v1::CANCELLED);
}

TEST(Server, FiftyRunsOnTwoBenchesWithPrioritiesAndCancellations) {
  ServerProcess server(TempDir("fifty"));
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto olga = MakeClient(addr, testing::kOperatorToken);

  std::vector<std::int64_t> low, high, all;
  v1::ExperimentSpec batch_low = ShortRun("low", 0.02, true, 0);
  batch_low.set_repeats(25);
  auto a = olga.Submit(batch_low);
  ASSERT_TRUE(a.ok()) << a.status().message();
  low.assign(a->run_ids().begin(), a->run_ids().end());
  v1::ExperimentSpec batch_high = ShortRun("high", 0.02, true, 5);
  batch_high.set_repeats(25);
  auto b = olga.Submit(batch_high);
  ASSERT_TRUE(b.ok()) << b.status().message();
  high.assign(b->run_ids().begin(), b->run_ids().end());
  ASSERT_EQ(low.size() + high.size(), 50u);
  // Cancel five low-priority runs that are still queued (the last ones: they wait behind 25 high ones).
  for (int k = 0; k < 5; ++k) {
    auto c = olga.Cancel(low[low.size() - 1 - k]);
    ASSERT_TRUE(c.ok()) << c.status().message();
    EXPECT_EQ(c->status(), v1::CANCELLED);
  }
  all = low;
  all.insert(all.end(), high.begin(), high.end());
  const auto runs = WaitAll(olga, all, 60.0);
  ASSERT_EQ(runs.size(), 50u);
  int done = 0, cancelled = 0;
  std::set<std::string> benches;
  double last_high_start = 0.0;
  for (const auto& r : runs) {
    done += r.status() == v1::DONE;
    cancelled += r.status() == v1::CANCELLED;
    if (r.status() == v1::DONE) benches.insert(r.bench());
    if (r.priority() == 5) last_high_start = std::max(last_high_start, r.started_unix_s());
  }
  EXPECT_EQ(done, 45);
  EXPECT_EQ(cancelled, 5);
  EXPECT_EQ(benches.size(), 2u) << "both benches worked";
  // Priority first: few low-priority runs can have started before the last high-priority one (those already
  // claimed when the high batch arrived).
  int low_before = 0;
  for (const auto& r : runs)
    if (r.priority() == 0 && r.status() == v1::DONE && r.started_unix_s() < last_high_start) ++low_before;
  EXPECT_LE(low_before, 4);
}

TEST(Server, KilledMidQueueLosesNothingAndRunsNothingTwice) {
  ServerProcess server(TempDir("kill"));
  std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto olga = MakeClient(addr, testing::kOperatorToken);
  v1::ExperimentSpec spec = ShortRun("k", 0.05, true, 0);
  spec.set_repeats(30);
  auto sub = olga.Submit(spec);
  ASSERT_TRUE(sub.ok()) << sub.status().message();
  const std::vector<std::int64_t> ids(sub->run_ids().begin(), sub->run_ids().end());
  // Killed while a run executes: a fixed 300 ms sleep sometimes landed between two runs' 50 ms (or before the
  // first started on a loaded machine) and nothing was interrupted. The newest run the store says is running
  // is killed within a few ms of being seen, well inside its 50 ms.
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  bool seen_running = false;
  while (!seen_running && std::chrono::steady_clock::now() < give_up) {
    for (std::int64_t id : ids) {
      auto r = olga.GetRun(id);
      if (r.ok() && r->status() == v1::RUNNING && r->progress() < 0.5) {
        seen_running = true;
        break;
      }
    }
  }
  ASSERT_TRUE(seen_running) << "no run was seen executing";
  server.Kill(SIGKILL);

  addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto again = MakeClient(addr, testing::kOperatorToken);
  const auto runs = WaitAll(again, ids, 60.0);
  ASSERT_EQ(runs.size(), 30u);
  int interrupted = 0;
  for (const auto& r : runs) {
    EXPECT_EQ(r.status(), v1::DONE) << r.id() << " " << r.reason();
    int dones = 0;
    for (const auto& h : r.history()) {
      dones += h.status() == v1::DONE;
      interrupted += h.status() == v1::INTERRUPTED;
    }
    EXPECT_EQ(dones, 1) << "run " << r.id() << " must complete exactly once";
    auto trace = again.GetTrace(r.id());
    ASSERT_TRUE(trace.ok()) << trace.status().message();
    EXPECT_EQ(trace->samples(), 501u) << "one trace per run, no duplicated chunks";
  }
  EXPECT_GE(interrupted, 1) << "runs were executing when the server was killed";
}

TEST(Server, WatchTraceAndCompareMatchTheLocalRun) {
  ServerProcess server(TempDir("watch"));
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto olga = MakeClient(addr, testing::kOperatorToken);
  auto spec = experiment::LoadSpecFile(std::string(VB_SOURCE_DIR) + "/examples/compare-current-controllers.json");
  ASSERT_TRUE(spec.ok());
  auto sub = olga.Submit(*spec);
  ASSERT_TRUE(sub.ok()) << sub.status().message();
  ASSERT_EQ(sub->run_ids_size(), 4);
  std::vector<v1::RunStatus> seen;
  auto st = olga.Watch(sub->run_ids(3), 30.0, 0.0, [&](const v1::RunEvent& ev) {
    seen.push_back(ev.status());
    return !Ended(ev.status());
  });
  ASSERT_TRUE(st.ok()) << st.message();
  ASSERT_FALSE(seen.empty());
  EXPECT_EQ(seen.back(), v1::DONE);
  const auto runs = WaitAll(olga, {sub->run_ids().begin(), sub->run_ids().end()}, 30.0);
  ASSERT_EQ(runs.size(), 4u);

  // The stored trace equals a local run of the same spec, sample for sample (the emulator is deterministic).
  auto points = experiment::ExpandSweep(*spec);
  ASSERT_TRUE(points.ok());
  auto e = experiment::BuildExperiment((*points)[0]);
  ASSERT_TRUE(e.ok());
  hw::EmulatedBench bench(experiment::EmulatedBenchFor(*e));
  experiment::Trace local;
  ASSERT_TRUE(experiment::Runner::Run(*e, bench, &local).ok());
  auto trace = olga.GetTrace(sub->run_ids(0));
  ASSERT_TRUE(trace.ok()) << trace.status().message();
  ASSERT_EQ(trace->samples(), local.size());
  const auto& i = trace->columns.at("i_A");
  for (size_t k = 0; k < local.size(); ++k) ASSERT_EQ(i[k], local.i_A[k]) << k;

  auto cmp = olga.Compare(sub->batch_id(), {});
  ASSERT_TRUE(cmp.ok()) << cmp.status().message();
  ASSERT_EQ(cmp->rows_size(), 4);
  EXPECT_EQ(cmp->rows(0).controller(), "fuzzy_current");
  EXPECT_EQ(cmp->rows(0).rank(), 1);
  EXPECT_GT(cmp->rows(0).metrics().at("effort_l2").mean(), 0.0);
  // Each row carries its case as fields and the runs it aggregates: together, the batch's runs.
  std::set<std::int64_t> compared;
  for (const auto& row : cmp->rows()) {
    EXPECT_EQ(row.key().name(), row.name()) << "no sweep: the case name is the spec name";
    EXPECT_EQ(row.key().repeat(), -1);
    ASSERT_EQ(row.run_ids_size(), 1) << row.name();
    compared.insert(row.run_ids(0));
  }
  EXPECT_EQ(compared, std::set<std::int64_t>(sub->run_ids().begin(), sub->run_ids().end()));
}

// GetTrace's max_points, from_s and to_s (api.proto): decimated and windowed on the server, peaks kept, bad
// requests refused naming the field.
TEST(Server, GetTraceDecimatesAndWindowsOnTheServer) {
  ServerProcess server(TempDir("trace"));
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto olga = MakeClient(addr, testing::kOperatorToken);
  auto sub = olga.Submit(ShortRun("trace", 0.5, false));  // 0.5 s at 10 kHz: 5001 samples
  ASSERT_TRUE(sub.ok()) << sub.status().message();
  const std::int64_t id = sub->run_ids(0);
  ASSERT_EQ(WaitAll(olga, {id}, 60.0).at(0).status(), v1::DONE);
  auto full = olga.GetTrace(id);
  ASSERT_TRUE(full.ok()) << full.status().message();
  const std::size_t n = full->samples();
  ASSERT_GT(n, 4000u);
  const auto& i_full = full->columns.at("i_A");
  const double period = full->sample_period_s;
  auto request = [&](std::int32_t max_points, double from_s, double to_s) {
    v1::GetTraceRequest r;
    r.set_run_id(id);
    r.set_max_points(max_points);
    r.set_from_s(from_s);
    r.set_to_s(to_s);
    return olga.GetTrace(r);
  };

  // Decimated: at most max_points rows, times in t_s, every channel's extremes kept.
  auto dec = request(200, 0, 0);
  ASSERT_TRUE(dec.ok()) << dec.status().message();
  EXPECT_TRUE(dec->decimated);
  EXPECT_EQ(dec->samples(), 200u);
  EXPECT_EQ(dec->total_samples, static_cast<std::int64_t>(n));
  EXPECT_EQ(std::count(dec->channels.begin(), dec->channels.end(), "t_s"), 0) << "times travel in t_s";
  ASSERT_EQ(dec->t_s.size(), dec->samples());
  EXPECT_TRUE(std::is_sorted(dec->t_s.begin(), dec->t_s.end()));
  for (const char* ch : {"i_A", "gate", "v_coil_V"}) {
    const auto& a = full->columns.at(ch);
    const auto& b = dec->columns.at(ch);
    EXPECT_EQ(*std::max_element(b.begin(), b.end()), *std::max_element(a.begin(), a.end())) << ch;
    EXPECT_EQ(*std::min_element(b.begin(), b.end()), *std::min_element(a.begin(), a.end())) << ch;
  }

  // A window, every sample: exactly the stored samples of [0.1, 0.12].
  auto win = request(0, 0.1, 0.12);
  ASSERT_TRUE(win.ok()) << win.status().message();
  EXPECT_FALSE(win->decimated);
  ASSERT_GE(win->samples(), 201u);
  ASSERT_LE(win->samples(), 203u);
  EXPECT_LE(win->TimeAt(0), 0.1 + 1e-12);
  EXPECT_GE(win->TimeAt(win->samples() - 1), 0.12 - 1e-12);
  for (std::size_t k = 0; k < win->samples(); ++k) {
    const auto at = static_cast<std::size_t>(std::lround((win->TimeAt(k) - full->t0_s) / period));
    ASSERT_EQ(win->columns.at("i_A")[k], i_full[at]) << k;
  }

  // A window decimated: rows inside it only, its peak kept.
  auto both = request(50, 0.1, 0.3);
  ASSERT_TRUE(both.ok()) << both.status().message();
  EXPECT_TRUE(both->decimated);
  EXPECT_LE(both->samples(), 50u);
  for (double t : both->t_s) {
    EXPECT_GE(t, 0.1 - period - 1e-12);
    EXPECT_LE(t, 0.3 + period + 1e-12);
  }
  const auto k0 = static_cast<std::ptrdiff_t>(std::floor(0.1 / period + 1e-9));
  const auto k1 = static_cast<std::ptrdiff_t>(std::ceil(0.3 / period - 1e-9)) + 1;
  const double window_max = *std::max_element(i_full.begin() + k0, i_full.begin() + k1);
  const auto& i_both = both->columns.at("i_A");
  EXPECT_EQ(*std::max_element(i_both.begin(), i_both.end()), window_max);

  // A window after the end: no rows, the channels still named.
  auto after = request(100, 10.0, 11.0);
  ASSERT_TRUE(after.ok()) << after.status().message();
  EXPECT_EQ(after->samples(), 0u);
  EXPECT_FALSE(after->channels.empty());

  // Bad requests: INVALID_ARGUMENT naming the field.
  for (std::int32_t bad : {-1, 1, 2000000}) {
    auto r = request(bad, 0, 0);
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument) << bad;
    EXPECT_EQ(r.status().message().rfind("max_points:", 0), 0u) << r.status().message();
  }
  auto nan_from = request(100, std::nan(""), 0);
  ASSERT_FALSE(nan_from.ok());
  EXPECT_EQ(nan_from.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(nan_from.status().message().rfind("from_s:", 0), 0u) << nan_from.status().message();
  auto inf_to = request(0, 0, INFINITY);
  ASSERT_FALSE(inf_to.ok());
  EXPECT_EQ(inf_to.status().message().rfind("to_s:", 0), 0u) << inf_to.status().message();
}

TEST(Server, SigtermStopsCleanlyAndTheRunResumesAfterRestart) {
  ServerProcess server(TempDir("term"));
  std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto olga = MakeClient(addr, testing::kOperatorToken);
  auto sub = olga.Submit(ShortRun("slow", 1.0, true));
  ASSERT_TRUE(sub.ok());
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const auto t0 = std::chrono::steady_clock::now();
  const int status = server.Kill(SIGTERM);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << server.Log();
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 3.0);
  EXPECT_NE(server.Log().find("shutting down"), std::string::npos);

  addr = server.Start();
  ASSERT_FALSE(addr.empty());
  auto again = MakeClient(addr, testing::kOperatorToken);
  const auto runs = WaitAll(again, {sub->run_ids(0)}, 30.0);
  ASSERT_EQ(runs.size(), 1u);
  EXPECT_EQ(runs[0].status(), v1::DONE);
}

// Issue 40: loop statistics travel on the run. A paced run executed by the server returns its ticks, overruns and
// jitter through GetRun (and ListRuns), with its wall time; a run not paced has an execution record but no loop
// statistics; both stay after the server restarts on its store (nothing is kept in the server's memory).
TEST(Server, APacedRunsLoopStatisticsComeBackWithTheRun) {
  ServerProcess server(TempDir("loopstats"));
  std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto olga = MakeClient(addr, testing::kOperatorToken);
  auto paced = olga.Submit(ShortRun("paced", 0.2, true));
  auto unpaced = olga.Submit(ShortRun("unpaced", 0.2, false));
  ASSERT_TRUE(paced.ok() && unpaced.ok()) << paced.status().message() << unpaced.status().message();
  const std::int64_t paced_id = paced->run_ids(0), unpaced_id = unpaced->run_ids(0);
  const auto runs = WaitAll(olga, {paced_id, unpaced_id}, 30.0);
  ASSERT_EQ(runs.size(), 2u);
  auto check = [&](client::Client& c, const char* when) {
    SCOPED_TRACE(when);
    auto p = c.GetRun(paced_id);
    ASSERT_TRUE(p.ok()) << p.status().message();
    ASSERT_EQ(p->status(), v1::DONE) << p->reason();
    ASSERT_TRUE(p->has_execution());
    EXPECT_GE(p->execution().wall_s(), 0.15) << "paced: about its duration in wall time";
    EXPECT_NEAR(p->execution().simulated_s(), 0.2, 1e-9);
    EXPECT_EQ(p->execution().samples(), 2001);
    ASSERT_TRUE(p->execution().has_loop()) << p->DebugString();
    const auto& loop = p->execution().loop();
    EXPECT_GT(loop.ticks(), 0);
    EXPECT_GE(loop.overruns(), 0);
    EXPECT_LE(loop.overruns(), loop.ticks());
    EXPECT_GE(loop.jitter_max_s(), loop.jitter_p99_s());
    EXPECT_GE(loop.jitter_p99_s(), loop.jitter_p50_s());
    auto u = c.GetRun(unpaced_id);
    ASSERT_TRUE(u.ok());
    ASSERT_TRUE(u->has_execution());
    EXPECT_EQ(u->execution().samples(), 2001);
    EXPECT_FALSE(u->execution().has_loop()) << "a run not paced has no loop statistics";
    v1::ListRunsRequest req;
    req.set_batch_id(paced->batch_id());
    auto listed = c.ListRuns(req);
    ASSERT_TRUE(listed.ok());
    ASSERT_EQ(listed->runs_size(), 1);
    ASSERT_TRUE(listed->runs(0).execution().has_loop());
    EXPECT_EQ(listed->runs(0).execution().loop().ticks(), loop.ticks());
  };
  check(olga, "as executed");
  const int status = server.Kill(SIGTERM);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << server.Log();
  addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto again = MakeClient(addr, testing::kViewerToken);
  check(again, "after a restart");
}

// Issue 39: a server killed mid-run dates the run's `interrupted` with the time it stopped (its spool's last sign
// of life), not the restart's; the spool (beside the SQLite file by default) holds nothing once the run is done.
double UnixNow() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}
TEST(Server, AKilledServersRunIsInterruptedAtTheStopNotTheRestart) {
  const std::string dir = TempDir("stopdate");
  ServerProcess server(dir);
  std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto olga = MakeClient(addr, testing::kOperatorToken);
  auto sub = olga.Submit(ShortRun("slow", 2.0, true));
  ASSERT_TRUE(sub.ok());
  std::this_thread::sleep_for(std::chrono::milliseconds(1300));
  const double killed_at = UnixNow();
  server.Kill(SIGKILL);
  std::this_thread::sleep_for(std::chrono::milliseconds(3500));
  const double restarted_at = UnixNow();
  addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto again = MakeClient(addr, testing::kOperatorToken);
  const auto runs = WaitAll(again, {sub->run_ids(0)}, 30.0);
  ASSERT_EQ(runs.size(), 1u);
  EXPECT_EQ(runs[0].status(), v1::DONE) << runs[0].reason();
  int interrupted = 0;
  for (const auto& h : runs[0].history()) {
    if (h.status() != v1::INTERRUPTED) continue;
    ++interrupted;
    // The uploader rewrites the alive file about every second (a loaded machine: a little more); a journal's
    // records are dated as they are written.
    EXPECT_GT(h.at_unix_s(), killed_at - 2.5);
    EXPECT_LT(h.at_unix_s(), killed_at + 0.1);
    EXPECT_LT(h.at_unix_s(), restarted_at - 3.0);
  }
  EXPECT_EQ(interrupted, 1);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  for (const auto& e : std::filesystem::directory_iterator(dir + "/runs.db.spool"))
    EXPECT_NE(e.path().extension(), ".journal") << e.path();
}

// A run whose spec says never_requeue stays interrupted after a crash; the others run again.
TEST(Server, NeverRequeueIsHonouredAfterACrash) {
  ServerProcess server(TempDir("norequeue"));
  std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto olga = MakeClient(addr, testing::kOperatorToken);
  auto once = ShortRun("once", 2.0, true);
  once.set_never_requeue(true);
  auto a = olga.Submit(once);
  auto b = olga.Submit(ShortRun("again", 2.0, true));
  ASSERT_TRUE(a.ok() && b.ok());
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // both execute, one per bench
  server.Kill(SIGKILL);
  addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto again = MakeClient(addr, testing::kOperatorToken);
  auto first = again.GetRun(a->run_ids(0));
  ASSERT_TRUE(first.ok());
  EXPECT_EQ(first->status(), v1::INTERRUPTED);
  const auto runs = WaitAll(again, {b->run_ids(0)}, 30.0);
  ASSERT_EQ(runs.size(), 1u);
  EXPECT_EQ(runs[0].status(), v1::DONE);
}

// TLS when a certificate and key are configured: a client that trusts the certificate works, a plaintext
// client does not get through.
TEST(Server, TlsWhenCertificateAndKeyAreConfigured) {
  const std::string dir = TempDir("tls");
  std::filesystem::create_directories(dir);
  const std::string gen = "openssl req -x509 -newkey rsa:2048 -nodes -days 2 -subj /CN=localhost "
                          "-addext subjectAltName=DNS:localhost,IP:127.0.0.1 -keyout " + dir + "/key.pem -out " +
                          dir + "/cert.pem > /dev/null 2>&1";
  ASSERT_EQ(std::system(gen.c_str()), 0) << "openssl is installed by scripts/setup.sh";
  ServerProcess server(dir, R"("tls": {"cert_file": "cert.pem", "key_file": "key.pem"})");
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  EXPECT_NE(server.Log().find("(TLS)"), std::string::npos);
  const std::string port = addr.substr(addr.rfind(':') + 1);

  std::ifstream in(dir + "/cert.pem");
  std::stringstream pem;
  pem << in.rdbuf();
  client::ClientOptions o;
  o.address = "localhost:" + port;
  o.token = testing::kViewerToken;
  o.tls_ca_pem = pem.str();
  o.deadline_s = 10;
  client::Client secure(o);
  auto b = secure.Benches();
  ASSERT_TRUE(b.ok()) << b.status().message();
  EXPECT_EQ(b->benches_size(), 2);

  client::ClientOptions plain = o;
  plain.tls_ca_pem.clear();
  plain.deadline_s = 3;
  client::Client insecure(plain);
  auto refused = insecure.Benches();
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kUnavailable) << refused.status().message();
}

}  // namespace
// Interactive runs: when the submitter's watch goes away mid-run, the run is cancelled (safe state); a
// non-interactive run watched the same way keeps running.
TEST(Server, InteractiveRunIsCancelledWhenItsClientDisconnects) {
  ServerProcess server(TempDir("interactive"));
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto olga = MakeClient(addr, testing::kOperatorToken);
  auto interactive = ShortRun("interactive", 20.0, true);
  interactive.set_interactive(true);
  auto a = olga.Submit(interactive);
  ASSERT_TRUE(a.ok()) << a.status().message();
  const std::int64_t id = a->run_ids(0);
  // Watch until it runs, then drop the stream (a disconnecting client: the deadline ends the call).
  bool running = false;
  (void)olga.Watch(id, 1.0, 0.0, [&](const v1::RunEvent& ev) {
    running = running || ev.status() == v1::RUNNING;
    return true;
  });
  ASSERT_TRUE(running);
  auto ended = WaitAll(olga, {id}, 5.0);
  ASSERT_EQ(ended.size(), 1u);
  EXPECT_EQ(ended[0].status(), v1::CANCELLED);
  EXPECT_NE(ended[0].reason().find("client disconnected"), std::string::npos) << ended[0].reason();
  EXPECT_LT(ended[0].finished_unix_s() - ended[0].started_unix_s(), 5.0);

  auto b = olga.Submit(ShortRun("plain", 20.0, true));
  ASSERT_TRUE(b.ok());
  (void)olga.Watch(b->run_ids(0), 1.0, 0.0, [](const v1::RunEvent&) { return true; });
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  auto still = olga.GetRun(b->run_ids(0));
  ASSERT_TRUE(still.ok());
  EXPECT_EQ(still->status(), v1::RUNNING) << "only interactive runs follow their client";
  ASSERT_TRUE(olga.Cancel(b->run_ids(0)).ok());
}

// ImportRuns validates the whole request before storing anything; errors name the run and the field.
TEST(Server, ImportRunsRefusesBadRunsAndStoresNothing) {
  ServerProcess server(TempDir("import"));
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto olga = MakeClient(addr, testing::kOperatorToken);
  v1::ImportRunsRequest req;
  req.set_dataset("lab7");
  auto add = [&](const char* id, std::vector<int> gate, std::vector<double> i) {
    auto* r = req.add_runs();
    r->set_id(id);
    r->set_supply_v(24.0);
    r->set_sample_period_s(2e-5);
    for (int g : gate) r->add_gate(g);
    for (double v : i) r->add_i_a(v);
    return r;
  };
  add("good", {0, 1, 1}, {0.0, 0.01, 0.02});
  add("bad", {0, 2, 1}, {0.0, 0.01, 0.02});
  auto refused = olga.ImportRuns(req);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.status().message().find("runs[1].gate[1]: must be 0 or 1"), std::string::npos)
      << refused.status().message();
  req.mutable_runs(1)->set_gate(1, 1);
  req.mutable_runs(1)->add_i_a(0.03);  // one current too many
  auto ragged = olga.ImportRuns(req);
  ASSERT_FALSE(ragged.ok());
  EXPECT_NE(ragged.status().message().find("runs[1].i_A: 4 samples for 3"), std::string::npos)
      << ragged.status().message();
  v1::ListRunsRequest all;
  auto listed = olga.ListRuns(all);
  ASSERT_TRUE(listed.ok());
  EXPECT_EQ(listed->runs_size(), 0) << "a refused import stores nothing";
  req.mutable_runs(1)->mutable_i_a()->RemoveLast();
  auto ok = olga.ImportRuns(req);
  ASSERT_TRUE(ok.ok()) << ok.status().message();
  EXPECT_EQ(ok->run_ids_size(), 2);
  auto viewer = MakeClient(addr, testing::kViewerToken);
  EXPECT_FALSE(viewer.ImportRuns(req).ok()) << "importing needs the operator role";
}

// A run larger than one gRPC message (1.5 M samples, about 25 MB) is streamed (ImportRunsStream) and stored
// chunk by chunk; a bad sample deep inside a streamed run fails that run with the field named, and the runs
// imported before stay. Bounds and duplicate ids are refused with the field named.
TEST(Server, ImportRunsStreamsRunsOfAnyLength) {
  ServerProcess server(TempDir("import_stream"));
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto olga = MakeClient(addr, testing::kOperatorToken);
  constexpr int kSamples = 1'500'000;
  auto make = [](const char* dataset) {
    v1::ImportRunsRequest req;
    req.set_dataset(dataset);
    auto* r = req.add_runs();
    r->set_id("long");
    r->set_supply_v(24.0);
    r->set_sample_period_s(1e-5);
    for (int k = 0; k < kSamples; ++k) {
      r->add_gate((k / 1000) % 2);
      r->add_i_a(1e-3 * (k % 997));
      r->add_x_m(1e-7 * (k % 13));
    }
    return req;
  };
  v1::ImportRunsRequest req = make("long");
  ASSERT_GT(req.ByteSizeLong(), 16u << 20) << "the request must be too large for one message";
  auto ok = olga.ImportRuns(req);
  ASSERT_TRUE(ok.ok()) << ok.status().message();
  ASSERT_EQ(ok->run_ids_size(), 1);
  auto trace = olga.GetTrace(ok->run_ids(0));
  ASSERT_TRUE(trace.ok()) << trace.status().message();
  ASSERT_EQ(trace->samples(), static_cast<size_t>(kSamples));
  for (int k : {0, 65535, 65536, 777777, kSamples - 1}) {
    EXPECT_EQ(trace->columns.at("i_A")[static_cast<size_t>(k)], 1e-3 * (k % 997)) << k;
    EXPECT_EQ(trace->columns.at("gate")[static_cast<size_t>(k)], (k / 1000) % 2) << k;
  }

  // A bad current deep in the second run of a streamed import: the first run stays imported, the second fails.
  v1::ImportRunsRequest two = make("two");
  *two.add_runs() = two.runs(0);
  two.mutable_runs(1)->set_id("long-2");
  two.mutable_runs(1)->set_t_start_s(100);
  two.mutable_runs(1)->set_i_a(1'234'567, 1e300);
  auto bad = olga.ImportRuns(two);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find("runs[1].i_A[1234567]: must be in [-1000, 1000] A, got 1e+300"),
            std::string::npos)
      << bad.status().message();
  v1::ListRunsRequest all;
  all.set_order_by("id");  // in import order (the default is newest first)
  auto listed = olga.ListRuns(all);
  ASSERT_TRUE(listed.ok());
  ASSERT_EQ(listed->runs_size(), 3);
  EXPECT_EQ(listed->total_size(), 3);
  EXPECT_EQ(listed->runs(1).status(), v1::DONE) << "the run imported before the bad one stays";
  EXPECT_EQ(listed->runs(2).status(), v1::FAILED);
  EXPECT_NE(listed->runs(2).reason().find("import failed: runs[1].i_A[1234567]"), std::string::npos)
      << listed->runs(2).reason();

  // Bounds and identity, small requests (one message): refused before anything is stored.
  v1::ImportRunsRequest small;
  small.set_dataset("small");
  auto* r = small.add_runs();
  r->set_id("a");
  r->set_supply_v(1e308);
  r->set_sample_period_s(1e-5);
  for (int k = 0; k < 3; ++k) {
    r->add_gate(0);
    r->add_i_a(0.0);
  }
  auto huge_supply = olga.ImportRuns(small);
  ASSERT_FALSE(huge_supply.ok());
  EXPECT_NE(huge_supply.status().message().find("runs[0].supply_V: must be in [0, 1000] V, got 1e+308"),
            std::string::npos)
      << huge_supply.status().message();
  r->set_supply_v(24);
  r->set_sample_period_s(1e-300);
  auto tiny_period = olga.ImportRuns(small);
  ASSERT_FALSE(tiny_period.ok());
  EXPECT_NE(tiny_period.status().message().find("runs[0].sample_period_s: must be in [1e-09, 10] s"),
            std::string::npos)
      << tiny_period.status().message();
  r->set_sample_period_s(1e-5);
  *small.add_runs() = small.runs(0);
  auto duplicate = olga.ImportRuns(small);
  ASSERT_FALSE(duplicate.ok());
  EXPECT_NE(duplicate.status().message().find("runs[1].id: \"a\" is also runs[0].id"), std::string::npos)
      << duplicate.status().message();
  auto after = olga.ListRuns(all);
  ASSERT_TRUE(after.ok());
  EXPECT_EQ(after->runs_size(), 3) << "refused imports store nothing";
}

}  // namespace vb
