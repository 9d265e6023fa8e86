// runs/: Admit and Execute, the one pipeline behind the server, the nights and benchctl's local mode.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <sstream>
#include <thread>

#include <unistd.h>

#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include "common/format.h"
#include "db/sqlite_store.h"
#include "db/store.h"
#include "db/testing.h"
#include "hw/emulated_bench.h"
#include "runs/admit.h"
#include "runs/monitor.h"
#include "runs/worker.h"
#include "tests/runs/flaky_store.h"

namespace vb::runs {
namespace {

std::string Example(const std::string& rel) { return std::string(VB_SOURCE_DIR) + "/examples/" + rel; }

experiment::ExperimentSpec E3() {
  auto spec = experiment::LoadSpecFile(Example("standard/e3.json"));
  EXPECT_TRUE(spec.ok()) << spec.status().ToString();
  return *spec;
}

// A server-like policy: one emulated bench of the default preset, and limits.
Policy ServerPolicy() {
  Policy p;
  BenchSetup b;
  b.name = "emu-1";
  b.kind = BenchKind::kEmulated;
  b.bench_class = "emulated:taghizadeh2009";
  b.caps.max_supply_V = 48;
  b.caps.max_carrier_Hz = 1e6;
  b.caps.max_sample_rate_Hz = 1e6;
  b.caps.max_control_rate_Hz = 1e6;
  b.caps.measures_position = true;
  b.caps.driver = "low_side_flyback";
  p.benches = {b};
  p.limits.max_duration_s = 1.0;
  p.limits.max_runs_per_submission = 10;
  return p;
}

// A run whose trace would not fit the per-run memory budget is refused at submission, naming what to lower.
TEST(Admit, ATraceOverTheMemoryBudgetIsRefusedAtSubmission) {
  Policy p = ServerPolicy();
  p.limits.max_trace_bytes_per_run = 10e6;  // 10 MB
  auto spec = E3();
  spec.set_duration_s(1.0);
  spec.mutable_recording()->set_rate_hz(1e6);  // 1e6 samples x 89 bytes = 89 MB
  auto a = Admit({"alice", "big", {spec}, {}, ""}, p);
  ASSERT_FALSE(a.ok());
  EXPECT_EQ(a.status().code(), StatusCode::kResourceExhausted);
  EXPECT_NE(a.status().message().find("recording: the trace would take 89 MB"), std::string::npos)
      << a.status().message();
  EXPECT_NE(a.status().message().find("over the per-run budget of 10 MB"), std::string::npos);
  spec.mutable_recording()->set_rate_hz(1e5);  // 8.9 MB: within it
  EXPECT_TRUE(Admit({"alice", "small", {spec}, {}, ""}, p).ok());
}

TEST(Admit, SweepAndRepeatsBecomeTypedKeysAndTags) {
  auto spec = E3();
  auto* ax = spec.add_sweep();
  ax->set_field("conditions.supply_V");
  ax->add_values(12);
  ax->add_values(15);
  spec.set_repeats(2);
  auto a = Admit({"alice", "b", {spec}, {}, ""}, ServerPolicy());
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_EQ(a->runs.size(), 4u);
  const db::RunRecord& r = a->runs[3];
  EXPECT_EQ(r.key, (RunKey{"e3", {{"conditions.supply_V", 15.0}}, 1}));
  EXPECT_EQ(r.bench_kind, "emulated:taghizadeh2009");
  EXPECT_EQ(r.controller, "open_loop_pwm");
  EXPECT_EQ(r.submitter, "alice");
  EXPECT_NE(std::find(r.tags.begin(), r.tags.end(), "repeat:1"), r.tags.end());
  EXPECT_FALSE(a->batch_json.empty());  // one spec: recorded verbatim
}

TEST(Admit, RefusalsNameTheRunAndTheField) {
  auto spec = E3();
  auto* ax = spec.add_sweep();
  ax->set_field("duration_s");
  ax->add_values(0.1);
  ax->add_values(5);
  auto a = Admit({"alice", "b", {spec}, {}, ""}, ServerPolicy());
  ASSERT_FALSE(a.ok());
  EXPECT_EQ(a.status().code(), StatusCode::kResourceExhausted);
  EXPECT_NE(a.status().message().find("run 1 (e3 sweep:duration_s=5): duration_s: 5 s exceeds"), std::string::npos)
      << a.status().message();

  auto hid = E3();
  hid.mutable_bench()->set_kind("hid");
  auto b = Admit({"alice", "b", {hid}, {}, ""}, ServerPolicy());
  ASSERT_FALSE(b.ok());
  EXPECT_EQ(b.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(b.status().message().find("bench: no configured bench can run it (needs hid"), std::string::npos)
      << b.status().message();

  auto keys = Admit({"alice", "b", {E3(), E3()}, {NamedRun("a")}, ""}, ServerPolicy());
  ASSERT_FALSE(keys.ok());
  EXPECT_NE(keys.status().message().find("keys: 1 keys for 2 specs"), std::string::npos) << keys.status().message();
}

TEST(Admit, GivenKeysReplaceTheSpecsOwnIdentity) {
  const RunKey key{"suite-case", {{"conditions.supply_V", 15.0}}, 0};
  auto a = Admit({"nights", "night:x", {E3()}, {key}, ""}, ServerPolicy());
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  EXPECT_EQ(a->runs[0].key, key);
}

TEST(Admit, TheLocalEmulatorTakesAnySpecWithoutLimits) {
  Policy local;
  local.benches = {LocalEmulatorSetup()};
  auto spec = E3();
  spec.mutable_bench()->set_kind("hid");   // no hid bench here: the local emulator plays it
  spec.mutable_bench()->set_name("rig-3");
  spec.set_duration_s(5);
  auto a = Admit({"me", "b", {spec}, {}, ""}, local);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  EXPECT_EQ(a->runs[0].bench_kind, "local");
  EXPECT_EQ(a->runs[0].bench_name, "");
}

TEST(Execute, AWorkerRunsTheQueueAndRecordsEveryRun) {
  auto store = db::OpenSqliteStore(":memory:");
  ASSERT_TRUE(store.ok());
  Policy local;
  local.benches = {LocalEmulatorSetup()};
  auto spec = E3();
  spec.set_repeats(2);
  auto a = Admit({"me", "b", {spec}, {}, ""}, local);
  ASSERT_TRUE(a.ok());
  auto q = Enqueue(store->get(), std::move(*a), local);
  ASSERT_TRUE(q.ok()) << q.status().ToString();
  Worker worker(LocalEmulatorSetup(), nullptr);
  for (int k = 0; k < 2; ++k) {
    auto o = worker.ClaimAndExecute(store->get());
    ASSERT_TRUE(o.ok()) << o.status().ToString();
    ASSERT_TRUE(o->has_value());
    EXPECT_EQ((*o)->status, db::RunStatus::kDone);
    EXPECT_TRUE((*o)->recorded);
    // The trace streamed to the store while the run executed; the Outcome keeps it only when asked.
    EXPECT_EQ((*o)->summary.samples, 5001u);
    EXPECT_EQ((*o)->trace.size(), 0u);
    std::int64_t stored = 0;
    ASSERT_TRUE((*store)->ForEachTraceChunk((*o)->run_id, [&](const db::TraceChunk&, std::int64_t total) {
      stored = total;
      return Status::Ok();
    }).ok());
    EXPECT_EQ(stored, 5001);
  }
  auto none = worker.ClaimAndExecute(store->get());
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->has_value());
  for (auto id : q->run_ids) {
    auto r = (*store)->GetRun(id);
    ASSERT_TRUE(r.ok());
    EXPECT_EQ(r->status, db::RunStatus::kDone);
    auto m = (*store)->GetMetrics(id);
    ASSERT_TRUE(m.ok());
    EXPECT_FALSE(m->empty());
    auto t = (*store)->ReadTrace(id);
    ASSERT_TRUE(t.ok());
    EXPECT_FALSE(t->empty());
  }
}

TEST(Execute, AStoredSpecThatNoLongerParsesFailsTheRunWithTheReason) {
  auto store = db::OpenSqliteStore(":memory:");
  ASSERT_TRUE(store.ok());
  db::RunRecord r;
  r.key = NamedRun("broken");
  r.bench_kind = "local";
  r.spec_json = "{\"no_such_field\": 1}";
  std::vector<std::int64_t> ids;
  ASSERT_TRUE((*store)->SubmitBatch("me", "b", "{}", {r}, &ids).ok());
  Worker worker(LocalEmulatorSetup(), nullptr);
  auto o = worker.ClaimAndExecute(store->get());
  ASSERT_TRUE(o.ok() && o->has_value());
  EXPECT_EQ((*o)->status, db::RunStatus::kFailed);
  EXPECT_EQ((*o)->summary.termination, experiment::RunSummary::Termination::kFailed);  // never started
  EXPECT_NE((*o)->summary.message.find("stored spec does not parse"), std::string::npos);
  auto got = (*store)->GetRun(ids[0]);
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(got->status, db::RunStatus::kFailed);
  EXPECT_NE(got->reason.find("stored spec does not parse"), std::string::npos) << got->reason;
}

// A run that fails at the bench marks the bench faulted (Outcome::bench_fault, set where the bench failed, not
// read back from the reason's text); a run that fails for any other reason does not.
TEST(Execute, ABenchThatCannotBeOpenedIsAFaultABadSpecIsNot) {
  auto store = db::OpenSqliteStore(":memory:");
  ASSERT_TRUE(store.ok());
  db::RunRecord r;
  r.key = NamedRun("on-hid");
  r.spec_json = R"({"name": "on-hid", "controller": {"open_loop_pwm": {"segments": [{"frequency_Hz": 0, "duty": 1}]}},
                    "conditions": {"supply_V": 24}, "duration_s": 0.01, "recording": {"rate_Hz": 10000}})";
  ASSERT_TRUE((*store)->SubmitBatch("me", "b", "{}", {r}, nullptr).ok());
  BenchSetup hid = LocalEmulatorSetup();
  hid.name = "hid-h3";
  hid.kind = BenchKind::kHid;
  hid.config.set_serial("no-such-device-serial");
  Worker faulty(hid, nullptr);
  auto o = faulty.ClaimAndExecute(store->get());
  ASSERT_TRUE(o.ok() && o->has_value());
  EXPECT_EQ((*o)->status, db::RunStatus::kFailed);
  EXPECT_TRUE((*o)->bench_fault) << (*o)->reason;
  EXPECT_EQ(faulty.fault(), (*o)->reason);

  db::RunRecord broken;
  broken.key = NamedRun("broken");
  broken.spec_json = R"({"no_such_field": 1, "note": "bench hid-h3: safety: looks like a fault"})";
  ASSERT_TRUE((*store)->SubmitBatch("me", "b", "{}", {broken}, nullptr).ok());
  Worker fine(LocalEmulatorSetup(), nullptr);
  o = fine.ClaimAndExecute(store->get());
  ASSERT_TRUE(o.ok() && o->has_value());
  EXPECT_EQ((*o)->status, db::RunStatus::kFailed);
  EXPECT_FALSE((*o)->bench_fault) << (*o)->reason;
  EXPECT_EQ(fine.fault(), "");
}

// Progress is by simulated time even between the loop's ticks: an open-loop run (one tick per segment) moves
// with its samples instead of sitting at 0 % until it ends.
TEST(Registry, ProgressFollowsTheSamplesBetweenTicks) {
  Registry registry;
  experiment::RunMonitor monitor;
  LiveTap tap(50);
  registry.Add(7, &monitor, &tap, 2.0);
  hw::BenchSample s{};
  s.t_s = 0.5;
  tap.OnSample(s);  // not a decimated one: the ring stays empty, the time still counts
  double progress = -1.0;
  ASSERT_TRUE(registry.Progress(7, &progress));
  EXPECT_DOUBLE_EQ(progress, 0.25);
  monitor.t_s.store(1.5);
  ASSERT_TRUE(registry.Progress(7, &progress));
  EXPECT_DOUBLE_EQ(progress, 0.75);
}

// A run re-claimed on the same host while its older attempt still runs there (docs/lab.md): the older attempt's
// end does not unregister the newer one.
TEST(Registry, AnOlderAttemptEndingLeavesTheNewerOneRegistered) {
  Registry registry;
  experiment::RunMonitor older, newer;
  LiveTap tap_old(1), tap_new(1);
  registry.Add(9, &older, &tap_old, 1.0);
  registry.Add(9, &newer, &tap_new, 1.0);
  registry.Remove(9, &older);
  ASSERT_TRUE(registry.Cancel(9));
  EXPECT_TRUE(newer.cancel.load());
  EXPECT_FALSE(older.cancel.load());
  registry.Remove(9, &newer);
  EXPECT_FALSE(registry.Cancel(9));
}

// Runs `spec` on the emulator with a live tap taking every `decimation`-th sample: the live samples and the trace.
::testing::AssertionResult RunTapped(const experiment::ExperimentSpec& spec, int decimation,
                                     std::vector<LiveSample>* live, experiment::Trace* trace) {
  auto e = experiment::BuildExperiment(spec);
  if (!e.ok()) return ::testing::AssertionFailure() << e.status().ToString();
  hw::EmulatedBench bench(experiment::EmulatedBenchFor(*e));
  LiveTap tap(decimation, &e->reference);
  experiment::RunMonitor monitor;
  if (auto st = experiment::Runner::Run(*e, bench, trace, &monitor, &tap); !st.ok())
    return ::testing::AssertionFailure() << st.message;
  tap.Drain(live);
  return ::testing::AssertionSuccess();
}

// The live stream carries the reference (issue 14: LiveSample.ref was always 0): a PI current law on the
// seed-001 profile, 0.9 A for 6 ms then 0.5 A.
TEST(LiveTap, SamplesCarryTheReferenceOfTheControlledVariable) {
  auto spec = experiment::LoadSpecFile(Example("compare-current-controllers.json"));
  ASSERT_TRUE(spec.ok()) << spec.status().ToString();
  spec->clear_variants();
  spec->set_duration_s(0.02);
  spec->clear_metric_window();
  std::vector<LiveSample> got;
  experiment::Trace trace;
  ASSERT_TRUE(RunTapped(*spec, 50, &got, &trace));
  ASSERT_GT(got.size(), 10u);
  for (const LiveSample& s : got) EXPECT_EQ(s.ref, s.t_s < 0.006 ? 0.9 : 0.5) << "t = " << s.t_s;
  // Without a profile (an open-loop run), NaN: "no reference", not a reference of 0.
  LiveTap open(50, nullptr);
  hw::BenchSample b{};
  b.t_s = 0.1;
  for (int k = 0; k < 50; ++k) open.OnSample(b);
  got.clear();
  open.Drain(&got);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_TRUE(std::isnan(got[0].ref));
}

// The live gate is each interval's duty (issue 37: a fast PWM streamed at 200 Hz drew as solid "on"). A 20 kHz
// PWM at duty 0.3 recorded at 50 kHz: the samples' mean aliases (five sample phases per two periods, one or two
// of them in the on-time: 0.2 or 0.4), the emulator's on-time integral gives 0.3.
TEST(LiveTap, EachSampleCarriesTheGatesExactDutyOverItsInterval) {
  auto spec = E3();
  spec.set_duration_s(0.02);
  auto* seg = spec.mutable_controller()->mutable_open_loop_pwm()->mutable_segments();
  seg->Clear();
  auto* s0 = seg->Add();
  s0->set_start_s(0.0);
  s0->set_frequency_hz(20000.0);
  s0->set_duty(0.3);
  std::vector<LiveSample> got;
  experiment::Trace trace;
  ASSERT_TRUE(RunTapped(spec, 50, &got, &trace));  // 50 kHz / 50: a live sample per ms
  ASSERT_GE(got.size(), 19u);
  double sampled_mean = 0.0;
  for (const double g : trace.gate) sampled_mean += g;
  sampled_mean /= static_cast<double>(trace.gate.size());
  // 0.4, or 0.2 where the sample that falls on a rising edge reads the level before it: aliased either way.
  EXPECT_GT(std::abs(sampled_mean - 0.3), 0.05) << "the recording's mean (what the page drew before)";
  for (std::size_t k = 1; k < got.size(); ++k) {
    EXPECT_NEAR(got[k].duty, 0.3, 1e-3) << "t = " << got[k].t_s;
    EXPECT_EQ(got[k].dropped_before, 0u);
  }

  // A bench without the on-time integral (hardware: NaN) gets the recorded samples' mean.
  LiveTap device(4);
  hw::BenchSample b{};
  b.gate_on_s = std::numeric_limits<double>::quiet_NaN();
  for (int k = 0; k < 8; ++k) {
    b.t_s = k * 1e-3;
    b.gate = static_cast<std::int8_t>(k == 1 || k >= 5 ? 1 : 0);
    device.OnSample(b);
  }
  got.clear();
  device.Drain(&got);
  ASSERT_EQ(got.size(), 2u);
  EXPECT_DOUBLE_EQ(got[0].duty, 0.25);
  EXPECT_DOUBLE_EQ(got[1].duty, 0.75);
}

// A full ring drops live samples without blocking the loop; the next sample that fits says how many were lost,
// and a watcher that fell behind the registry's backlog is told how many it missed (RunEvent.dropped_samples).
TEST(LiveTap, LossesAreCountedWhereTheyHappen) {
  LiveTap tap(1);
  hw::BenchSample b{};
  const int fed = 8192 + 10;  // the ring holds 8191
  for (int k = 0; k < fed; ++k) {
    b.t_s = k * 1e-3;
    tap.OnSample(b);
  }
  std::vector<LiveSample> got;
  tap.Drain(&got);
  ASSERT_EQ(got.size(), 8191u);
  for (const auto& s : got) EXPECT_EQ(s.dropped_before, 0u);
  b.t_s = fed * 1e-3;
  tap.OnSample(b);
  got.clear();
  tap.Drain(&got);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].dropped_before, 11u);

  Registry registry;
  experiment::RunMonitor monitor;
  LiveTap live(1);
  registry.Add(3, &monitor, &live, 100.0);
  std::uint64_t fast = 0, slow = 0, missed = 0;
  std::vector<LiveSample> out;
  for (int round = 0; round < 4; ++round) {  // 4 x 6000 samples: the fast watcher reads each round
    for (int k = 0; k < 6000; ++k) {
      b.t_s = (round * 6000 + k) * 1e-3;
      live.OnSample(b);
    }
    out.clear();
    ASSERT_TRUE(registry.SamplesSince(3, &fast, &out, &missed));
    EXPECT_EQ(out.size(), 6000u);
  }
  EXPECT_EQ(missed, 0u);
  out.clear();
  ASSERT_TRUE(registry.SamplesSince(3, &slow, &out, &missed));  // the backlog keeps the newest 16384
  EXPECT_EQ(out.size(), 16384u);
  EXPECT_EQ(missed, 24000u - 16384u);
}

// A kept sample speaks for the ones thinned out before it: their mean duty and their summed losses.
TEST(SampleThinner, AKeptSampleCarriesTheDutyAndLossesOfWhatItStandsFor) {
  SampleThinner thin(250.0);  // a 1 kHz stream thinned to one in four
  double duty = -1.0;
  std::uint64_t lost = 99;
  std::vector<std::pair<double, std::uint64_t>> kept;
  for (int k = 0; k < 12; ++k) {
    const double d = k % 4 == 0 ? 1.0 : 0.0;  // the interval's duty
    if (thin.Keep(k * 1e-3, d, k == 5 ? 3 : 0, &duty, &lost)) kept.emplace_back(duty, lost);
  }
  ASSERT_EQ(kept.size(), 3u);  // at 0, 4 and 8 ms
  EXPECT_DOUBLE_EQ(kept[0].first, 1.0);   // the first stands for itself
  EXPECT_DOUBLE_EQ(kept[1].first, 0.25);  // 1, 2, 3 and 4 ms: one of four on
  EXPECT_EQ(kept[1].second, 0u);
  EXPECT_EQ(kept[2].second, 3u);          // lost before 5 ms, reported with the 8 ms sample
}

// WatchRun's sample_rate_Hz (issue 14: 0 and 10 Hz both streamed 1 kHz).
TEST(SampleThinner, KeepsAtMostTheRequestedRateAndNoneForZero) {
  auto kept = [](double rate_Hz) {
    SampleThinner thin(rate_Hz);
    int n = 0;
    for (int k = 0; k < 2000; ++k) n += thin.Keep(k * 1e-3);  // 2 s of a 1 kHz stream
    return n;
  };
  EXPECT_EQ(kept(0.0), 0);
  EXPECT_EQ(kept(-1.0), 0);
  EXPECT_EQ(kept(10.0), 20);
  EXPECT_EQ(kept(1000.0), 2000);
  EXPECT_EQ(kept(1e6), 2000);  // never more than the stream has
  EXPECT_EQ(kept(3.0), 6);
}

// A run cancelled half-way keeps the progress it reached (issue 14: every cancelled run read 0 %).
TEST(Execute, ACancelledRunKeepsTheProgressItReached) {
  auto store = db::OpenSqliteStore(":memory:");
  ASSERT_TRUE(store.ok());
  Policy local;
  local.benches = {LocalEmulatorSetup()};
  auto spec = E3();
  spec.set_duration_s(1.0);
  spec.set_realtime(true);  // paced: 1 s of wall time, so the cancel lands mid-run
  auto a = Admit({"me", "b", {spec}, {}, ""}, local);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  auto q = Enqueue(store->get(), std::move(*a), local);
  ASSERT_TRUE(q.ok()) << q.status().ToString();
  const std::int64_t id = q->run_ids[0];
  Registry registry;
  Worker worker(LocalEmulatorSetup(), &registry);
  std::thread canceller([&] {
    double progress = 0.0;
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    while ((!registry.Progress(id, &progress) || progress < 0.2) && std::chrono::steady_clock::now() < until)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    registry.Cancel(id);
  });
  auto o = worker.ClaimAndExecute(store->get());
  canceller.join();
  ASSERT_TRUE(o.ok() && o->has_value());
  EXPECT_EQ((*o)->status, db::RunStatus::kCancelled);
  auto r = (*store)->GetRun(id);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->status, db::RunStatus::kCancelled);
  EXPECT_GE(r->progress, 0.2);
  EXPECT_LT(r->progress, 0.9);
  EXPECT_NEAR(r->progress, (*o)->summary.duration_s / 1.0, 1e-9);
}

// Per-user disk budget (issue 14 item 1): what the user's traces take, plus the new runs' traces counted
// uncompressed, must fit; the refusal names the limit and what to do.
TEST(Enqueue, APerUserDiskBudgetCountsStoredTracesAndTheNewRunsUncompressed) {
  auto store = db::OpenSqliteStore(":memory:");
  ASSERT_TRUE(store.ok());
  Policy p = ServerPolicy();
  auto spec = E3();  // 0.1 s at 50 kHz: 5 002 samples x 12 x 8 B = 480 kB uncompressed
  auto a = Admit({"alice", "first", {spec}, {}, ""}, p);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  EXPECT_EQ(a->trace_bytes_raw, 5002.0 * 12 * 8);  // the samples the Runner reserves
  p.limits.max_disk_bytes_per_user = 1e6;  // 1 MB
  auto q = Enqueue(store->get(), *a, p);
  ASSERT_TRUE(q.ok()) << q.status().ToString();
  // The run stores 700 kB of (incompressible) trace: alice's next 480 kB no longer fit, bob's do.
  db::TraceChunk c;
  c.sample_period_s = 1e-5;
  c.samples = 45000;  // 2 x 45 000 random doubles: 720 kB, incompressible
  c.channels = {"noise", "noise2"};
  std::uint64_t x = 88172645463325252ULL;
  for (int k = 0; k < 2 * c.samples; ++k) {
    x ^= x << 13, x ^= x >> 7, x ^= x << 17;
    c.data.push_back(std::bit_cast<double>(x & 0x7fefffffffffffffULL));
  }
  // Only the attempt holding a run writes its trace: claim it first.
  auto queued = (*store)->GetRun(q->run_ids[0]);
  ASSERT_TRUE(queued.ok());
  auto claimed = (*store)->ClaimNext(db::BenchClaim(queued->bench_kind, "bench-1"));
  ASSERT_TRUE(claimed.ok() && claimed->has_value());
  ASSERT_TRUE((*store)->AppendTraceChunk(db::LeaseOf(**claimed), c).ok());
  auto used = (*store)->StoredTraceBytes("alice");
  ASSERT_TRUE(used.ok());
  EXPECT_GT(*used, 700000);
  EXPECT_EQ(*(*store)->StoredTraceBytes("bob"), 0);
  auto b = Admit({"alice", "second", {spec}, {}, ""}, p);
  ASSERT_TRUE(b.ok());
  auto refused = Enqueue(store->get(), *b, p);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kResourceExhausted);
  EXPECT_NE(refused.status().message().find("limits.max_disk_MB_per_user: user alice's stored traces take"),
            std::string::npos)
      << refused.status().message();
  EXPECT_NE(refused.status().message().find("benchctl prune"), std::string::npos);
  auto other = Admit({"bob", "first", {spec}, {}, ""}, p);
  ASSERT_TRUE(other.ok());
  EXPECT_TRUE(Enqueue(store->get(), *other, p).ok());
}

// A cancel that cuts a long bench step short (the interlocks split it and watch the cancel flag) states where
// the bench got to, not the end of the step it was in (issue 14: "cancelled at t = 600 s" for a run stopped at
// 420 s, and progress 100 %).
// The trace reaches the store in chunks while the run executes (what a watcher on another host reads), and
// the run keeps none of it in memory (its length does not matter: perf_emulator's long-run figure shows 3 M
// samples in flat memory, docs/perf.md).
TEST(Execute, TheTraceIsInTheStoreWhileTheRunExecutes) {
  const std::string path = ::testing::TempDir() + "/streaming_" + std::to_string(::getpid()) + ".db";
  for (const char* suffix : {"", "-wal", "-shm"}) std::remove((path + suffix).c_str());
  auto store = db::OpenSqliteStore(path);
  ASSERT_TRUE(store.ok());
  // Paced to the wall clock, so the run lasts its 2 s however loaded the machine is and the watcher (polling
  // every 2 ms) cannot miss it: unpaced, a 3 M-sample run takes 0.6 s and a starved watcher saw only its end.
  BenchSetup bench = LocalEmulatorSetup();
  bench.paced = true;
  Policy local;
  local.benches = {bench};
  auto spec = experiment::LoadSpecFile(Example("standard/e1.json"));
  ASSERT_TRUE(spec.ok());
  spec->set_duration_s(2);
  auto a = Admit({"me", "b", {*spec}, {}, ""}, local);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  auto q = Enqueue(store->get(), std::move(*a), local);
  ASSERT_TRUE(q.ok());
  const std::int64_t id = q->run_ids[0];
  std::atomic<bool> finished{false}, watching{false};
  // The smallest non-empty trace seen while the run was running: a part of it, if chunks arrive as it runs (the
  // largest is the whole trace, seen between its last chunk and the run's end).
  std::int64_t seen_while_running = 0;
  std::thread watcher([&] {
    auto other = db::OpenSqliteStore(path);  // another connection, as another host would have
    watching.store(true);  // the run starts only now: opening a connection on a loaded machine can outlast it
    if (!other.ok()) return;
    while (!finished.load()) {
      auto run = (*other)->GetRun(id);
      if (run.ok() && run->status == db::RunStatus::kRunning) {
        std::int64_t samples = 0;
        (void)(*other)->ForEachTraceChunk(id, [&](const db::TraceChunk&, std::int64_t total) {
          samples = total;
          return Status::Ok();
        });
        if (samples > 0 && (seen_while_running == 0 || samples < seen_while_running)) seen_while_running = samples;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  });
  while (!watching.load()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  Worker worker(bench, nullptr);
  auto o = worker.ClaimAndExecute(store->get());
  finished.store(true);
  watcher.join();
  ASSERT_TRUE(o.ok() && o->has_value());
  ASSERT_EQ((*o)->status, db::RunStatus::kDone) << (*o)->reason;
  EXPECT_EQ((*o)->summary.samples, 100'001u);
  EXPECT_GT(seen_while_running, 0) << "no chunk was in the store before the run finished";
  EXPECT_LT(seen_while_running, 100'001) << "the watcher only ever saw the finished trace";
  EXPECT_EQ((*o)->trace.size(), 0u);
  for (const char* suffix : {"", "-wal", "-shm"}) std::remove((path + suffix).c_str());
}

// benchctl run --local has no interlocks: the bare emulator itself stops a ten-minute PWM segment (one Runner
// step) at the next edge once the flag is set, so the cancel lands inside the run, not at its end.
TEST(Execute, ACancelLandsInsideALongStepOnTheBareEmulator) {
  auto store = db::OpenSqliteStore(":memory:");
  ASSERT_TRUE(store.ok());
  BenchSetup bench = LocalEmulatorSetup();
  ASSERT_FALSE(bench.interlocks);
  Policy local;
  local.benches = {bench};
  auto spec = experiment::LoadSpecFile(Example("standard/e1.json"));
  ASSERT_TRUE(spec.ok());
  spec->set_duration_s(600);
  spec->mutable_recording()->set_rate_hz(1000);
  auto a = Admit({"me", "b", {*spec}, {}, ""}, local);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  auto q = Enqueue(store->get(), std::move(*a), local);
  ASSERT_TRUE(q.ok());
  const std::int64_t id = q->run_ids[0];
  Registry registry;
  Worker worker(bench, &registry);
  std::thread canceller([&] {
    double progress = 0.0;
    while (!registry.Progress(id, &progress)) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    registry.Cancel(id);
  });
  auto o = worker.ClaimAndExecute(store->get());
  canceller.join();
  ASSERT_TRUE(o.ok() && o->has_value());
  ASSERT_EQ((*o)->status, db::RunStatus::kCancelled) << (*o)->reason;
  EXPECT_LT((*o)->summary.last_sample_t_s, 599.0) << "the cancel waited for the end of the segment";
  EXPECT_LT((*o)->summary.samples, 599'000u);
}

TEST(Execute, ACancelInsideALongStepStatesTheTimeTheBenchReached) {
  auto store = db::OpenSqliteStore(":memory:");
  ASSERT_TRUE(store.ok());
  BenchSetup bench = LocalEmulatorSetup();
  bench.interlocks = true;  // as on a server bench
  bench.safety.max_current_A = 100;
  Policy local;
  local.benches = {bench};
  auto spec = experiment::LoadSpecFile(Example("standard/e1.json"));
  ASSERT_TRUE(spec.ok());
  spec->set_duration_s(600);  // open loop: one bench step to the end (no control ticks in between)
  spec->mutable_recording()->set_rate_hz(1000);
  auto a = Admit({"me", "b", {*spec}, {}, ""}, local);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  auto q = Enqueue(store->get(), std::move(*a), local);
  ASSERT_TRUE(q.ok());
  const std::int64_t id = q->run_ids[0];
  Registry registry;
  Worker worker(bench, &registry);
  std::thread canceller([&] {
    double progress = 0.0;
    while (!registry.Progress(id, &progress)) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
    registry.Cancel(id);
  });
  auto o = worker.ClaimAndExecute(store->get());
  canceller.join();
  ASSERT_TRUE(o.ok() && o->has_value());
  ASSERT_EQ((*o)->status, db::RunStatus::kCancelled) << (*o)->reason;
  const double reached = (*o)->summary.last_sample_t_s;
  auto chunks = (*store)->ReadTrace(id);
  ASSERT_TRUE(chunks.ok() && !chunks->empty());
  const db::TraceChunk& last = chunks->back();
  EXPECT_DOUBLE_EQ(last.t0_s + last.sample_period_s * (last.samples - 1), reached) << "the stored trace ends there";
  EXPECT_LT(reached, 599.0) << "the cancel did not land inside the run";
  auto r = (*store)->GetRun(id);
  ASSERT_TRUE(r.ok());
  EXPECT_NE(r->reason.find("cancelled at t = " + FormatNumber(reached) + " s of 600 s"), std::string::npos)
      << r->reason;
  EXPECT_NEAR(r->progress, reached / 600.0, 1e-9);
}


// ---- A run that survives its store (issue 30; docs/lab.md, "When the database fails") ----

namespace store_faults {

using runs::testing::FlakyStore;

// One E3 run queued on a SQLite store, claimed as host "h" (a lease of 10 s); the claimed record.
struct Queued {
  std::unique_ptr<db::Store> store;
  db::RunRecord run;
};
Queued QueueAndClaim() {
  Queued q;
  auto store = db::OpenSqliteStore(":memory:");
  EXPECT_TRUE(store.ok());
  q.store = std::move(*store);
  Policy local;
  local.benches = {LocalEmulatorSetup()};
  auto a = Admit({"me", "b", {E3()}, {}, ""}, local);
  EXPECT_TRUE(a.ok());
  auto e = Enqueue(q.store.get(), std::move(*a), local);
  EXPECT_TRUE(e.ok());
  db::ClaimRequest claim = db::BenchClaim(LocalEmulatorSetup().bench_class, LocalEmulatorSetup().name);
  claim.host = "h";
  claim.lease_ttl_s = 10;
  auto c = q.store->ClaimNext(claim);
  EXPECT_TRUE(c.ok() && c->has_value());
  q.run = **c;
  return q;
}

std::int64_t StoredSamples(db::Store* store, std::int64_t id) {
  std::int64_t stored = 0;
  EXPECT_TRUE(store->ForEachTraceChunk(id, [&](const db::TraceChunk&, std::int64_t total) {
    stored = total;
    return Status::Ok();
  }).ok());
  return stored;
}

TEST(StoreFaults, ARunWhoseStoreIsDownWhileItRunsIsWrittenWhenTheStoreReturns) {
  Queued q = QueueAndClaim();
  FlakyStore flaky(q.store.get());
  flaky.down = true;  // from before the first chunk to after the end of the run
  std::atomic<bool> ended{false};
  ExecuteContext ctx;
  ctx.retry.give_up_s = 30;
  ctx.ended = [&] { ended = true; };
  std::thread back([&] {
    while (!ended) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the result waits ~0.3 s for the store
    flaky.down = false;
  });
  Outcome o = Execute(&flaky, q.run, LocalEmulatorSetup(), ctx);
  back.join();
  EXPECT_GT(flaky.failed_writes.load(), 1);
  EXPECT_TRUE(o.recorded);
  EXPECT_FALSE(o.released);
  EXPECT_FALSE(o.stale);
  EXPECT_EQ(o.status, db::RunStatus::kDone) << o.reason;
  auto r = q.store->GetRun(q.run.id);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->status, db::RunStatus::kDone) << r->reason;
  EXPECT_EQ(StoredSamples(q.store.get(), q.run.id), 5001);  // the chunks kept while it was down, in order
  EXPECT_FALSE(q.store->GetMetrics(q.run.id)->empty());
}

TEST(StoreFaults, AnswersLostAfterTheirCommitAreNotStaleWritesNorWrittenTwice) {
  Queued q = QueueAndClaim();
  FlakyStore flaky(q.store.get());
  flaky.lose_chunk_answers = 1;
  flaky.lose_finish_answers = 1;
  ExecuteContext ctx;
  Outcome o = Execute(&flaky, q.run, LocalEmulatorSetup(), ctx);
  EXPECT_EQ(flaky.failed_writes.load(), 2);
  EXPECT_TRUE(o.recorded);
  EXPECT_FALSE(o.stale);
  EXPECT_EQ(o.status, db::RunStatus::kDone) << o.reason;
  EXPECT_EQ(StoredSamples(q.store.get(), q.run.id), 5001);
  std::int64_t stale = -1;
  ASSERT_TRUE(q.store->StaleWrites(10, &stale).ok());
  EXPECT_EQ(stale, 0);
  auto hist = q.store->History(q.run.id);
  ASSERT_TRUE(hist.ok());
  EXPECT_EQ(std::count_if(hist->begin(), hist->end(),
                          [](const db::StatusChange& c) { return c.status == db::RunStatus::kDone; }),
            1);
}

TEST(StoreFaults, AResultTheStoreNeverTakesIsReleasedNotFailed) {
  Queued q = QueueAndClaim();
  FlakyStore flaky(q.store.get());
  flaky.down = true;
  ExecuteContext ctx;
  ctx.retry.give_up_s = 0.3;
  Outcome o = Execute(&flaky, q.run, LocalEmulatorSetup(), ctx);
  EXPECT_TRUE(o.released);
  EXPECT_FALSE(o.recorded);
  auto r = q.store->GetRun(q.run.id);
  ASSERT_TRUE(r.ok());
  // Still running under a lease nobody renews: it lapses and the lab runs it again; never failed.
  EXPECT_EQ(r->status, db::RunStatus::kRunning);
}

TEST(StoreFaults, ARunIsNoLongerExecutingWhileItsResultWaitsForTheStore) {
  Queued q = QueueAndClaim();
  // Give the run back to the queue so a Worker claims it itself.
  ASSERT_TRUE(q.store->RecoverAfterCrash("h").ok());
  FlakyStore flaky(q.store.get());
  flaky.fail_finishes = 1000000;
  Worker worker(LocalEmulatorSetup(), nullptr);
  worker.set_claim_policy({"h", 10.0, 0.0, 1.0});  // the result is held 1 s
  std::atomic<bool> done{false};
  StatusOr<std::optional<Outcome>> o = std::optional<Outcome>();
  std::thread t([&] {
    o = worker.ClaimAndExecute(&flaky);
    done = true;
  });
  bool seen_waiting = false;
  int executing_while_waiting = 0;
  while (!done) {
    if (flaky.finish_calls.load() > 0) {
      seen_waiting = true;
      executing_while_waiting += worker.executing_lease().run_id != 0;
      // A progress write now would race the result: WithExecutingLease does not call it.
      bool called = false;
      EXPECT_TRUE(worker.WithExecutingLease([&](const db::Lease&) {
        called = true;
        return Status::Ok();
      }).ok());
      EXPECT_FALSE(called);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  t.join();
  EXPECT_TRUE(seen_waiting);
  EXPECT_EQ(executing_while_waiting, 0);
  ASSERT_TRUE(o.ok() && o->has_value());
  EXPECT_TRUE((*o)->released);
  EXPECT_EQ(worker.executing_lease().run_id, 0);
}

TEST(StoreFaults, AFaultIsLoggedOnceWhenItBeginsAndOnceWithItsLengthWhenItEnds) {
  std::ostringstream out;
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(out);
  auto previous = spdlog::default_logger();
  spdlog::set_default_logger(std::make_shared<spdlog::logger>("test", sink));
  {
    FaultLog log("bench emu-1");
    log.Recovered();  // no fault: nothing
    for (int k = 0; k < 100; ++k) log.Failed(Status::Unavailable("store unavailable: down"));
    EXPECT_TRUE(log.in_fault());
    log.Recovered();
    log.Recovered();
    EXPECT_FALSE(log.in_fault());
  }
  spdlog::set_default_logger(previous);
  const std::string text = out.str();
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 2) << text;
  EXPECT_NE(text.find("bench emu-1: store unavailable, retrying"), std::string::npos) << text;
  EXPECT_NE(text.find("bench emu-1: store reachable again after"), std::string::npos) << text;
  EXPECT_NE(text.find("(100 call(s) failed meanwhile)"), std::string::npos) << text;
}

TEST(StoreFaults, RetryWriteRetriesOnlyTransientErrorsAndGivesUpWhenTold) {
  RetryPolicy fast;
  fast.first_wait_s = 0.001;
  fast.max_wait_s = 0.002;
  int calls = 0;
  // Transient twice, then done.
  Status st = RetryWrite(
      [&] { return ++calls < 3 ? Status::Unavailable("store unavailable: x") : Status::Ok(); }, fast, nullptr);
  EXPECT_TRUE(st.ok());
  EXPECT_EQ(calls, 3);
  // Aborted (a deadlock, a lock timeout) is transient too.
  calls = 0;
  st = RetryWrite([&] { return ++calls < 2 ? Status::Aborted("deadlock") : Status::Ok(); }, fast, nullptr);
  EXPECT_TRUE(st.ok());
  EXPECT_EQ(calls, 2);
  // Fenced and permanent errors: once, returned as they are.
  for (const Status& once : {Status::FailedPrecondition("stale write: x"), Status::InvalidArgument("progress: x"),
                             Status::Internal("bug")}) {
    calls = 0;
    st = RetryWrite([&] { ++calls; return once; }, fast, nullptr);
    EXPECT_EQ(st.code(), once.code());
    EXPECT_EQ(calls, 1);
  }
  // Given up after give_up_s, or at once when stopping: the last transient error.
  fast.give_up_s = 0.05;
  st = RetryWrite([] { return Status::Unavailable("store unavailable: down"); }, fast, nullptr);
  EXPECT_EQ(st.code(), StatusCode::kUnavailable);
  std::atomic<bool> stop{true};
  fast.give_up_s = 1e9;
  fast.stop = &stop;
  calls = 0;
  st = RetryWrite([&] { ++calls; return Status::Unavailable("store unavailable: down"); }, fast, nullptr);
  EXPECT_EQ(st.code(), StatusCode::kUnavailable);
  EXPECT_EQ(calls, 1);
}

}  // namespace store_faults

}  // namespace
}  // namespace vb::runs
