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

// Collects what a stream delivers: the blocks' sizes and first indices, and the samples themselves.
class CollectingSink final : public BlockSink {
 public:
  Status OnBlock(const Trace& block, std::uint64_t first_sample) override {
    if (fail_at_block >= 0 && static_cast<int>(firsts.size()) == fail_at_block)
      return Status::FailedPrecondition("stale write: the store refused the chunk");
    firsts.push_back(first_sample);
    sizes.push_back(block.size());
    for (size_t k = 0; k < block.size(); ++k) {
      t_s.push_back(block.t_s[k]);
      i_A.push_back(block.i_A[k]);
    }
    return Status::Ok();
  }
  int fail_at_block = -1;
  std::vector<std::uint64_t> firsts;
  std::vector<size_t> sizes;
  std::vector<double> t_s, i_A;
};

// Every experiment kind, streamed in small blocks: the same samples in order, and the same metrics as the
// whole trace gives (MetricsAccumulator against ComputeMetrics), while the run holds only a few blocks.
TEST(Runner, AStreamedTraceHasEverySampleInOrderAndTheSameMetrics) {
  for (const char* example : {"standard/e1.json", "standard/e2.json", "standard/e3.json",
                              "compare-position-controllers.json", "compare-current-controllers.json"}) {
    SCOPED_TRACE(example);
    auto spec = LoadSpecFile(Example(example));
    ASSERT_TRUE(spec.ok());
    auto points = ExpandRuns(*spec);
    ASSERT_TRUE(points.ok() && !points->empty());
    auto e = BuildExperiment(points->back().spec);
    ASSERT_TRUE(e.ok()) << e.status().message();
    Ran whole;
    {
      hw::EmulatedBench bench(EmulatedBenchFor(*e));
      whole.summary = Runner::Run(*e, bench, &whole.trace);
    }
    ASSERT_TRUE(whole.summary.ok());
    CollectingSink sink;
    RunOptions options;
    options.block_sink = &sink;
    options.block_samples = 997;  // no divisor of anything: blocks end at odd places
    options.stream_blocks = 2;
    Trace streamed;
    hw::EmulatedBench bench(EmulatedBenchFor(*e));
    const RunSummary s = Runner::Run(*e, bench, &streamed, options);
    ASSERT_TRUE(s.ok()) << s.message;
    EXPECT_EQ(streamed.size(), 0u) << "the whole trace is not kept unless asked";
    ASSERT_EQ(sink.t_s.size(), whole.trace.size());
    EXPECT_EQ(s.samples, whole.trace.size());
    for (size_t k = 0; k < sink.t_s.size(); ++k) {
      ASSERT_EQ(sink.t_s[k], whole.trace.t_s[k]) << k;
      ASSERT_EQ(sink.i_A[k], whole.trace.i_A[k]) << k;
    }
    std::uint64_t next = 0;
    for (size_t b = 0; b < sink.firsts.size(); ++b) {
      EXPECT_EQ(sink.firsts[b], next);
      EXPECT_LE(sink.sizes[b], 997u);
      next += sink.sizes[b];
    }
    EXPECT_DOUBLE_EQ(s.last_sample_t_s, whole.trace.t_s.back());
    const auto a = MetricList(whole.summary.metrics), b = MetricList(s.metrics);
    for (size_t m = 0; m < a.size(); ++m) {
      if (std::isnan(a[m].second)) {
        EXPECT_TRUE(std::isnan(b[m].second)) << a[m].first;
      } else {
        EXPECT_NEAR(b[m].second, a[m].second, 1e-12 * std::max(1.0, std::abs(a[m].second))) << a[m].first;
      }
    }
  }
}

// A store that refuses a chunk (a stale lease, a full disk) fails the run with the reason and leaves the
// bench safe; nothing after the refused block is delivered.
TEST(Runner, ARefusedBlockFailsTheRunWithTheReasonAndTheBenchSafe) {
  auto spec = LoadSpecFile(Example("standard/e3.json"));
  ASSERT_TRUE(spec.ok());
  auto e = BuildExperiment(*spec);
  ASSERT_TRUE(e.ok());
  hw::EmulatedBench bench(EmulatedBenchFor(*e));
  CollectingSink sink;
  sink.fail_at_block = 2;
  RunOptions options;
  options.block_sink = &sink;
  options.block_samples = 500;
  Trace trace;
  const RunSummary s = Runner::Run(*e, bench, &trace, options);
  EXPECT_EQ(s.termination, RunSummary::Termination::kFailed);
  EXPECT_NE(s.message.find("recording: stale write"), std::string::npos) << s.message;
  EXPECT_EQ(sink.firsts.size(), 2u);
  EXPECT_EQ(bench.simulator().gate(), 0);
}

// keep_whole_trace: the caller asked for every sample as well (benchctl run --trace-csv).
TEST(Runner, AStreamedRunCanKeepTheWholeTraceWhenAsked) {
  auto spec = LoadSpecFile(Example("standard/e1.json"));
  ASSERT_TRUE(spec.ok());
  auto e = BuildExperiment(*spec);
  ASSERT_TRUE(e.ok());
  hw::EmulatedBench bench(EmulatedBenchFor(*e));
  CollectingSink sink;
  RunOptions options;
  options.block_sink = &sink;
  options.keep_whole_trace = true;
  Trace trace;
  const RunSummary s = Runner::Run(*e, bench, &trace, options);
  ASSERT_TRUE(s.ok());
  ASSERT_EQ(trace.size(), sink.t_s.size());
  EXPECT_EQ(trace.t_s.back(), sink.t_s.back());
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
