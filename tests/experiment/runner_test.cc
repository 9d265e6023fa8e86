// The whole local path: spec file -> Runner -> EmulatedBench -> trace, against the reference solver.
#include <gtest/gtest.h>

#include <cmath>

#include "../model/perfref.h"
#include "experiment/runner.h"
#include "hw/emulated_bench.h"

namespace vb::experiment {
namespace {

std::string Example(const std::string& rel) { return std::string(VB_SOURCE_DIR) + "/examples/" + rel; }

struct Ran {
  RunSummary summary;
  Trace trace;
};

Ran RunSpec(const ExperimentSpec& spec) {
  auto e = BuildExperiment(spec);
  EXPECT_TRUE(e.ok()) << e.status().message();
  hw::EmulatedBench bench(EmulatedBenchFor(*e));
  Ran r;
  r.summary = Runner::Run(*e, bench, &r.trace);
  return r;
}

class StandardExperiment : public ::testing::TestWithParam<const char*> {};

TEST_P(StandardExperiment, TraceMatchesTheReferenceSolver) {
  const std::string name = GetParam();
  auto spec = LoadSpecFile(Example("standard/" + name + ".json"));
  ASSERT_TRUE(spec.ok()) << spec.status().message();
  Ran r = RunSpec(*spec);
  ASSERT_TRUE(r.summary.ok()) << r.summary.message;
  std::string upper = name;
  upper[0] = 'E';
  const auto ref = vb::testing::LoadRefTrace(upper);
  ASSERT_EQ(r.trace.size(), ref.t_s.size());
  double se = 0;
  for (size_t k = 0; k < ref.t_s.size(); ++k) {
    ASSERT_NEAR(r.trace.t_s[k], ref.t_s[k], 1e-9);
    se += std::pow(r.trace.i_A[k] - ref.i_A[k], 2);
  }
  EXPECT_LT(std::sqrt(se / ref.t_s.size()), 1e-8);
  EXPECT_EQ(r.trace.dropped, 0u);
}

INSTANTIATE_TEST_SUITE_P(Examples, StandardExperiment, ::testing::Values("e1", "e2", "e3"));

TEST(Runner, GateChannelFollowsTheSchedule) {
  auto spec = LoadSpecFile(Example("standard/e1.json"));
  ASSERT_TRUE(spec.ok());
  Ran r = RunSpec(*spec);
  // 50 Hz, duty 0.4: gate high on [0, 8 ms) of each 20 ms period; samples every 20 us.
  for (size_t k = 0; k + 1 < r.trace.size(); ++k) {
    const double phase = std::fmod(r.trace.t_s[k] + 1e-9, 0.02);
    ASSERT_EQ(r.trace.gate[k], phase < 0.008 ? 1 : 0) << "t = " << r.trace.t_s[k];
  }
  EXPECT_EQ(r.summary.metrics.switches, 100.0);  // 50 falls, 49 rises inside, and the rise at t = 1 s (last sample)
  EXPECT_NEAR(r.summary.metrics.opening_delay_s, 4.06e-3, 2e-5);
}

TEST(Runner, CancelStopsTheRunAndLeavesTheBenchSafe) {
  auto spec = LoadSpecFile(Example("standard/e1.json"));
  ASSERT_TRUE(spec.ok());
  auto e = BuildExperiment(*spec);
  ASSERT_TRUE(e.ok());
  hw::EmulatedBench bench(EmulatedBenchFor(*e));
  std::atomic<bool> cancel{true};
  Trace trace;
  RunSummary s = Runner::Run(*e, bench, &trace, &cancel);
  EXPECT_EQ(s.termination, RunSummary::Termination::kCancelled);
  EXPECT_EQ(bench.simulator().gate(), 0);
}

// A trace no memory can hold fails the run with the reason; it does not end the process (std::bad_alloc).
TEST(Runner, ATraceThatCannotBeReservedFailsTheRunWithTheReason) {
  auto spec = LoadSpecFile(Example("standard/e1.json"));
  ASSERT_TRUE(spec.ok());
  auto e = BuildExperiment(*spec);
  ASSERT_TRUE(e.ok());
  e->duration_s = 1e9;  // 1e9 s at the spec's rate: beyond any vector's max_size
  e->run.sample_rate_Hz = 1e6;
  hw::EmulatedBench bench(EmulatedBenchFor(*e));
  Trace trace;
  RunSummary s = Runner::Run(*e, bench, &trace);
  EXPECT_EQ(s.termination, RunSummary::Termination::kFailed);
  EXPECT_NE(s.message.find("recording: cannot reserve memory"), std::string::npos) << s.message;
}

TEST(Runner, RealtimeRunReportsJitter) {
  auto spec = LoadSpecFile(Example("standard/e3.json"));
  ASSERT_TRUE(spec.ok());
  spec->set_duration_s(0.05);
  spec->set_realtime(true);
  // A 1 kHz control tick so that the pacing has something to measure.
  auto* seg = spec->mutable_controller()->mutable_open_loop_pwm()->mutable_segments(0);
  seg->set_frequency_hz(1000.0);
  seg->set_duty(0.5);
  spec->mutable_controller()->mutable_open_loop_pwm()->mutable_segments()->DeleteSubrange(1, 1);
  for (int k = 1; k < 50; ++k) {
    auto* s = spec->mutable_controller()->mutable_open_loop_pwm()->add_segments();
    s->set_start_s(k * 1e-3);
    s->set_frequency_hz(1000.0);
    s->set_duty(0.5);
  }
  Ran r = RunSpec(*spec);
  ASSERT_TRUE(r.summary.ok()) << r.summary.message;
  EXPECT_GE(r.summary.loop.ticks, 50u);
  EXPECT_GE(r.summary.wall_s, 0.045) << "a paced run takes at least its duration";
  EXPECT_LE(r.summary.loop.jitter_p50_s, r.summary.loop.jitter_max_s);
}

}  // namespace
}  // namespace vb::experiment
