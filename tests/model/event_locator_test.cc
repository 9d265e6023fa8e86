// The event locator alone (model/event_locator.h): what the simulator relies on when it places stops, current
// zeros and driver thresholds inside an integration step. And the simulator's loop with it: no allocation.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "model/event_locator.h"
#include "model/simulator.h"
#include "sim_util.h"
#include "tests/control/alloc_counter.h"

namespace vb::model {
namespace {

// Counts the evaluations of g that the locator asks for.
struct Counted {
  double (*fn)(double);
  int calls = 0;
  double operator()(double t) {
    ++calls;
    return fn(t);
  }
};

TEST(EventLocator, FindsTheBracketedRootOfASmoothFunction) {
  Counted g{[](double t) { return std::cos(t); }};
  EventLocatorOptions opt;  // 1e-14 s, as the simulator uses it
  const EventHit hit = LocateEvent(g, 0.0, g(0.0), 2.0, g(2.0), opt);
  ASSERT_EQ(hit.found, EventFound::kCrossing);
  EXPECT_TRUE(hit.converged);
  const double root = M_PI / 2;
  // The answer is the upper end of the final bracket: on or just past the root, within the tolerance.
  EXPECT_GE(hit.t_s, root - 4e-16);
  EXPECT_LE(hit.t_s, root + opt.time_tol_s);
  EXPECT_LE(std::cos(hit.t_s), 0.0);
  // TOMS 748 converges superlinearly: bisection would need ~48 halvings of [0, 2] to reach 1e-14.
  EXPECT_LT(hit.evaluations, 20u);
  EXPECT_EQ(static_cast<int>(hit.evaluations), g.calls - 2);  // the two end values are in g.calls too
}

TEST(EventLocator, ARootAtTheEndOfTheStepIsThatEnd) {
  Counted g{[](double t) { return 1.0 - t; }};
  const EventHit hit = LocateEvent(g, 0.0, 1.0, 1.0, 0.0, EventLocatorOptions{});
  ASSERT_EQ(hit.found, EventFound::kCrossing);
  EXPECT_EQ(hit.t_s, 1.0);
  EXPECT_EQ(g.calls, 0);
}

TEST(EventLocator, AStepStartingOnTheSurfaceFindsWhereItCrossesAgain) {
  // g(0) = 0, positive on (0, 0.5), negative after: just lifted, the spool comes back to the stop at 0.5.
  Counted g{[](double t) { return t * (0.5 - t); }};
  const EventHit hit = LocateEvent(g, 0.0, 0.0, 1.0, g(1.0), EventLocatorOptions{});
  ASSERT_EQ(hit.found, EventFound::kCrossing);
  EXPECT_NEAR(hit.t_s, 0.5, 1e-14);
  EXPECT_GE(hit.t_s, 0.5);
}

TEST(EventLocator, AStepStartingOnTheSurfaceAndGoingPastItAtOnceIsAnEventAtTheStart) {
  Counted g{[](double t) { return -t; }};
  const EventHit hit = LocateEvent(g, 0.25, 0.0, 1.0, -0.75, EventLocatorOptions{});
  ASSERT_EQ(hit.found, EventFound::kAtStart);
  EXPECT_EQ(hit.t_s, 0.25);
  EXPECT_EQ(static_cast<int>(hit.evaluations), g.calls);  // the probes, all <= 0
  EXPECT_GT(g.calls, 10);
}

TEST(EventLocator, StayingOnTheSurfaceOrRoundOffBelowItIsNoEvent) {
  Counted zero{[](double) { return 0.0; }};
  EXPECT_EQ(LocateEvent(zero, 0.0, 0.0, 1.0, 0.0, EventLocatorOptions{}).found, EventFound::kNone);
  // A spool at rest with zero net force drifting by round-off: far below on_surface_g.
  Counted drift{[](double t) { return -1e-12 * t; }};
  EXPECT_EQ(LocateEvent(drift, 0.0, 0.0, 1.0, -1e-12, EventLocatorOptions{}).found, EventFound::kNone);
}

TEST(EventLocator, NoSignChangeIsNoEventAndCostsNoEvaluation) {
  Counted g{[](double t) { return 1.0 + t * t; }};
  const EventHit hit = LocateEvent(g, -1.0, 2.0, 1.0, 2.0, EventLocatorOptions{});
  EXPECT_EQ(hit.found, EventFound::kNone);
  EXPECT_EQ(g.calls, 0);
  // A function that dips below zero and comes back inside the step is invisible from its ends: the simulator's
  // max_step_s is what bounds such grazing contacts.
  Counted dip{[](double t) { return std::abs(t - 0.5) - 0.1; }};
  EXPECT_EQ(LocateEvent(dip, 0.0, 0.4, 1.0, 0.4, EventLocatorOptions{}).found, EventFound::kNone);
}

TEST(EventLocator, TheToleranceIsHonoured) {
  const double root = std::log(1.0 / 0.3);
  auto f = [](double t) { return std::exp(-t) - 0.3; };
  for (double tol : {1e-14, 1e-10, 1e-6, 1e-2}) {
    Counted g{f};
    EventLocatorOptions opt;
    opt.time_tol_s = tol;
    const EventHit hit = LocateEvent(g, 0.0, f(0.0), 4.0, f(4.0), opt);
    ASSERT_EQ(hit.found, EventFound::kCrossing) << tol;
    EXPECT_TRUE(hit.converged) << tol;
    // The root lies in the final bracket, whose upper end is the answer.
    EXPECT_GE(hit.t_s, root - 4e-16) << tol;
    EXPECT_LE(hit.t_s, root + tol) << tol;
    EXPECT_LE(f(hit.t_s), 0.0) << tol;
  }
  // A step already narrower than the tolerance is not searched: its end is the answer.
  Counted g{f};
  EventLocatorOptions wide;
  wide.time_tol_s = 1e-3;
  const EventHit hit = LocateEvent(g, root - 4e-4, f(root - 4e-4), root + 4e-4, f(root + 4e-4), wide);
  ASSERT_EQ(hit.found, EventFound::kCrossing);
  EXPECT_EQ(hit.t_s, root + 4e-4);
  EXPECT_EQ(g.calls, 0);  // the end values were given
}

TEST(EventLocator, TheEvaluationBudgetIsHonoured) {
  // A sign-only function: no interpolation helps, the solver must fall back to bisection.
  auto step = [](double t) { return t < 0.3 ? 1.0 : -1.0; };
  for (std::uintmax_t budget : {3u, 8u, 30u}) {
    Counted g{step};
    EventLocatorOptions opt;
    opt.max_evaluations = budget;
    const EventHit hit = LocateEvent(g, 0.0, 1.0, 1.0, -1.0, opt);
    ASSERT_EQ(hit.found, EventFound::kCrossing);
    EXPECT_FALSE(hit.converged) << budget;
    EXPECT_LE(hit.evaluations, budget);
    EXPECT_EQ(static_cast<int>(hit.evaluations), g.calls);
    // Out of budget the answer is still a bracket end on or past the event.
    EXPECT_GE(hit.t_s, 0.3);
    EXPECT_LE(hit.t_s, 1.0);
    EXPECT_LE(step(hit.t_s), 0.0);
  }
  Counted g{step};
  EventLocatorOptions opt;
  opt.time_tol_s = 1e-9;
  const EventHit hit = LocateEvent(g, 0.0, 1.0, 1.0, -1.0, opt);
  EXPECT_TRUE(hit.converged);
  EXPECT_NEAR(hit.t_s, 0.3, 1e-9);
}

TEST(EventLocator, NaNCountsAsPastTheEvent) {
  auto f = [](double t) { return t < 0.7 ? 0.7 - t : std::numeric_limits<double>::quiet_NaN(); };
  Counted g{f};
  EventLocatorOptions opt;
  opt.time_tol_s = 1e-12;
  const EventHit hit = LocateEvent(g, 0.0, 0.7, 1.0, f(1.0), opt);
  ASSERT_EQ(hit.found, EventFound::kCrossing);
  EXPECT_TRUE(std::isfinite(hit.t_s));
  EXPECT_NEAR(hit.t_s, 0.7, 1e-12);
}

TEST(EventLocator, LocatingAllocatesNothing) {
  Counted g{[](double t) { return std::cos(t); }};
  const long before = vb::testing::g_allocations.load();
  const EventHit hit = LocateEvent(g, 0.0, 1.0, 2.0, std::cos(2.0), EventLocatorOptions{});
  EXPECT_EQ(vb::testing::g_allocations.load(), before);
  EXPECT_EQ(hit.found, EventFound::kCrossing);
}

// The real-time path (docs/model.md, "Real-time"): AdvanceTo allocates nothing, with every piece of the split
// at work: moving spool (events located on the dense output), closed-form pieces, the driver's freewheel and
// current zero, and the sensor's lag and latency ring.
struct CountSamples final : SimObserver {
  long samples = 0, events[8] = {};
  void OnSample(const PlantSample&) override { ++samples; }
  void OnEvent(EventKind kind, double, double, double, double) override { ++events[static_cast<int>(kind)]; }
};

long AllocationsOverFivePeriodsOfE1(const PlantParams& p, CountSamples* obs, std::uint64_t* ode_steps) {
  Plant plant(p);
  Simulator sim(plant, DriverParams{}, Conditions{24.0, 4e5});
  sim.SetSamplePeriod(2e-5);  // sizes the sensor's ring: outside the loop
  const long before = vb::testing::g_allocations.load();
  const double T = 1.0 / 50.0;  // E1's PWM (tests/model/simulator_test.cc)
  for (int n = 0; n < 5; ++n) {
    sim.AdvanceTo(n * T, obs);
    sim.SetGate(1);
    sim.AdvanceTo(n * T + 0.4 * T, obs);
    sim.SetGate(0);
    (void)sim.measured_current_A();
  }
  sim.AdvanceTo(5 * T, obs);
  const long allocated = vb::testing::g_allocations.load() - before;
  EXPECT_FALSE(sim.failed()) << sim.failure();
  *ode_steps = sim.ode_steps();
  return allocated;
}

TEST(Simulator, AdvanceToAllocatesNothing) {
  PlantParams p = *Preset("taghizadeh2009");
  ASSERT_TRUE(AddEffect(&p.effects, "sensor_lag", {{"tau_s", 2e-5}, {"delay_s", 3e-5}}).ok());
  CountSamples obs;
  std::uint64_t steps = 0;
  EXPECT_EQ(AllocationsOverFivePeriodsOfE1(p, &obs, &steps), 0);
  EXPECT_GT(steps, 100u);
  EXPECT_EQ(obs.samples, 5000);
  // E1's spool opens and is released every period; it closes fully only after the first (the current does
  // not decay far enough in 12 ms), so it lifts off the lower stop twice.
  EXPECT_EQ(obs.events[static_cast<int>(EventKind::kOpen)], 5);
  EXPECT_EQ(obs.events[static_cast<int>(EventKind::kRelease)], 5);
  EXPECT_EQ(obs.events[static_cast<int>(EventKind::kLift)], 2);
  EXPECT_EQ(obs.events[static_cast<int>(EventKind::kClose)], 1);
  // The general path (every piece integrated) with the eddy branch's terminal current.
  ASSERT_TRUE(AddEffect(&p.effects, "eddy_currents", {{"R_p", 400.0}}).ok());
  CountSamples eddy;
  EXPECT_EQ(AllocationsOverFivePeriodsOfE1(p, &eddy, &steps), 0);
  EXPECT_GT(steps, 500u);
  EXPECT_EQ(eddy.samples, 5000);
}

}  // namespace
}  // namespace vb::model
