// The hold of a nightly health check (gap/hold.h, issue 38): the winding's resistance and the held coil's
// inductance measured from a PWM hold simulated by the event-exact emulator, without a model of the valve.
#include "gap/hold.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "gap/replay.h"
#include "gap/track.h"
#include "model/params.h"

namespace vb::gap {
namespace {

struct HoldPlan {
  double supply_V = 24.0;
  double pull_in_s = 0.01;
  double hold_s = 0.04;
  double frequency_Hz = 1000.0;
  double duty = 0.5;
  double noise_A = 1e-3;
  unsigned seed = 1;
  double pre_s = 1e-4;    // the gate low before the switch-on (the baseline)
  double offset_A = 0.0;  // the scope's baseline offset
  double tail_s = 0.0;    // the gate low after the hold (the drop-out)
};

// A hold run as the health check records it: the gate low 0.1 ms, high for the pull-in, then PWM (then, with
// tail_s, the gate low: the drop-out); the current with white noise; no coil voltage (the driver's voltages are
// used).
RunData SimulateHold(const model::PlantParams& plant, const HoldPlan& plan) {
  constexpr double dt = 1e-5;
  const auto n =
      static_cast<std::size_t>(std::llround((plan.pre_s + plan.pull_in_s + plan.hold_s + plan.tail_s) / dt)) + 1;
  RunData r;
  r.id = "hold";
  r.supply_V = plan.supply_V;
  r.sample_period_s = dt;
  r.gate.resize(n);
  const auto period = static_cast<long>(std::llround(1.0 / plan.frequency_Hz / dt));
  const auto high = static_cast<long>(std::llround(plan.duty / plan.frequency_Hz / dt));
  const auto on = static_cast<long>(std::llround(plan.pre_s / dt)),
             hold = on + static_cast<long>(std::llround(plan.pull_in_s / dt)),
             tail = hold + static_cast<long>(std::llround(plan.hold_s / dt));
  for (std::size_t k = 0; k < n; ++k) {
    const long j = static_cast<long>(k);
    r.gate[k] = j < on ? 0 : j < hold ? 1 : j >= tail && plan.tail_s > 0.0 ? 0 : ((j - hold) % period) < high ? 1 : 0;
  }
  ReplayInput in;
  in.supply_V = plan.supply_V;
  in.sample_period_s = dt;
  in.gate = r.gate;
  auto rep = ReplayRun(plant, model::DriverParams{}, in);
  EXPECT_TRUE(rep.ok()) << rep.status().message();
  std::mt19937 rng(plan.seed);
  std::normal_distribution<double> noise(0.0, plan.noise_A);
  for (std::size_t k = 0; k < n; ++k) {
    r.t_s.push_back(static_cast<double>(k) * dt);
    r.i_A.push_back(rep->i_A[k] + noise(rng) + plan.offset_A);
  }
  if (plan.tail_s == 0.0) {
    EXPECT_NEAR(rep->x_m.back(), plant.x_max_m, 1e-9) << "the plunger is held through the hold";
  }
  return r;
}

model::PlantParams Valve() {
  auto p = model::Preset(model::kDefaultPreset);
  EXPECT_TRUE(p.ok());
  return *p;
}

TEST(Hold, MeasuresTheWindingsResistanceWithoutAModelOfTheValve) {
  const auto plant = Valve();
  const auto m = MeasureHold(SimulateHold(plant, {}), model::DriverParams{});
  ASSERT_TRUE(m.ok()) << m.status().message();
  EXPECT_EQ(m->periods, 19);  // the rises in the second half of 40 periods bound 19 whole ones
  EXPECT_NEAR(m->duty, 0.5, 0.01);
  EXPECT_NEAR(m->frequency_Hz, 1000.0, 1.0);
  EXPECT_FALSE(m->voltage_measured);
  // The resistance to its sigma's scale: the integrals are exact up to the sampling of the current, and the
  // settling still under way (the current falls 0.1-0.3 % a period here) is taken out through L. Without
  // that correction the periods' values run from 12.78 to 13.12 ohm.
  EXPECT_NEAR(m->R_ohm / plant.R_ohm, 1.0, 0.002) << m->R_ohm << " ohm";
  EXPECT_GT(m->R_sigma_ohm, 0.0);
  EXPECT_LT(m->R_sigma_ohm, 0.001 * plant.R_ohm);
  EXPECT_GT(m->L_H, 0.0);
  EXPECT_LT(m->L_sigma_H, 0.02 * m->L_H);
}

// A scope's baseline offset is the mean before the gate rises (the health check records 5 ms of it); a short
// baseline leaves it, and R then carries it (-5 mA is 0.55 % of the 0.91 A hold: the test asks for 0.4 %).
TEST(Hold, RemovesTheScopesOffsetFromTheBaselineBeforeTheGate) {
  const auto plant = Valve();
  HoldPlan plan;
  plan.pre_s = 5e-3, plan.offset_A = -5e-3, plan.hold_s = 0.1;
  const auto m = MeasureHold(SimulateHold(plant, plan), model::DriverParams{});
  ASSERT_TRUE(m.ok()) << m.status().message();
  EXPECT_NEAR(m->offset_A, -5e-3, 3e-4);
  EXPECT_NEAR(m->R_ohm / plant.R_ohm, 1.0, 0.001) << m->R_ohm;
  plan.pre_s = 1e-4;  // 10 samples: no baseline
  const auto left = MeasureHold(SimulateHold(plant, plan), model::DriverParams{});
  ASSERT_TRUE(left.ok()) << left.status().message();
  EXPECT_EQ(left->offset_A, 0.0);
  EXPECT_GT(left->R_ohm / plant.R_ohm, 1.004) << left->R_ohm;
}

TEST(Hold, SeparatesAResistanceChangeFromShortedTurns) {
  const auto plant = Valve();
  const auto base = MeasureHold(SimulateHold(plant, {}), model::DriverParams{});
  ASSERT_TRUE(base.ok()) << base.status().message();
  // A winding 3 % more resistive: R_hold follows, L_hold does not.
  auto warmer = plant;
  warmer.R_ohm *= 1.03;
  HoldPlan other_noise;
  other_noise.seed = 2;
  const auto w = MeasureHold(SimulateHold(warmer, other_noise), model::DriverParams{});
  ASSERT_TRUE(w.ok()) << w.status().message();
  EXPECT_NEAR(w->R_ohm / base->R_ohm, 1.03, 0.003);
  EXPECT_NEAR(w->L_H / base->L_H, 1.0, 0.01);
  // 5 % of the turns shorted (this plant keeps R): the inductance falls with the square of the turns left.
  auto shorted = plant;
  shorted.N_turns *= 0.95;
  const auto s = MeasureHold(SimulateHold(shorted, other_noise), model::DriverParams{});
  ASSERT_TRUE(s.ok()) << s.status().message();
  EXPECT_NEAR(s->R_ohm / base->R_ohm, 1.0, 0.003);
  EXPECT_LT(s->L_H / base->L_H, 0.95);
  EXPECT_GT(s->L_H / base->L_H, 0.85);
}

TEST(Hold, RefusesWhatItCannotMeasureAndSaysWhy) {
  const auto plant = Valve();
  HoldPlan shortp;
  shortp.hold_s = 0.004;  // two periods in the second half
  auto m = MeasureHold(SimulateHold(plant, shortp), model::DriverParams{});
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.status().message().find("whole PWM period(s)"), std::string::npos) << m.status().message();
  // No coil voltage and a driver that does not say it from the gate.
  model::DriverParams bridge;
  bridge.kind = model::DriverKind::kHBridge;
  m = MeasureHold(SimulateHold(plant, {}), bridge);
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.status().message().find("record v_coil_V"), std::string::npos) << m.status().message();
  // A switch-on is not a hold, and TakeHoldRuns leaves it in the dataset.
  Dataset ds;
  RunData on;
  on.id = "on";
  on.gate = {0, 0, 1, 1, 1};
  ds.runs.push_back(on);
  ds.runs.push_back(SimulateHold(plant, {}));
  EXPECT_FALSE(IsHoldRun(on));
  const auto holds = TakeHoldRuns(&ds);
  ASSERT_EQ(holds.size(), 1u);
  ASSERT_EQ(ds.runs.size(), 1u);
  EXPECT_EQ(ds.runs[0].id, "on");
  std::vector<std::string> notes;
  const auto values = HoldValues(holds, model::DriverParams{}, &notes);
  ASSERT_EQ(values.size(), 2u);
  EXPECT_EQ(values[0].name, "R_hold");
  EXPECT_EQ(values[1].name, "L_hold");
  EXPECT_TRUE(notes.empty());
  EXPECT_TRUE(HoldValues({on}, model::DriverParams{}, &notes).empty());
  EXPECT_EQ(notes.size(), 1u);
}

// Two captures whose mean is not the coil's, found by the fuzz target (fuzz/hold_fuzz.cc) reading confident
// values: a scope's range that clips the ripple's top, and a hold measured while the current is still far from
// settled, where the settling correction (L times the change) would carry most of R.
TEST(Hold, RefusesAClippedRippleAndACurrentStillSettling) {
  const auto plant = Valve();
  RunData clipped = SimulateHold(plant, {});
  const auto m = MeasureHold(clipped, model::DriverParams{});
  ASSERT_TRUE(m.ok()) << m.status().message();
  const double clip_A = m->hold_current_A + m->offset_A;  // the range ends at the hold's mean current
  for (double& i : clipped.i_A) i = std::min(i, clip_A);
  auto c = MeasureHold(clipped, model::DriverParams{});
  ASSERT_FALSE(c.ok()) << "a clipped hold read R = " << c->R_ohm << " ohm against " << plant.R_ohm;
  EXPECT_NE(c.status().message().find("clipped"), std::string::npos) << c.status().message();

  // The same valve with a tenth of the resistance: L/R ten times longer, and 40 ms of hold are a fraction of it.
  // Here the ripple reads L right and the correction would have given 1.2956 ohm for 1.3; the rule refuses it
  // anyway, for the L a ripple misreads (gap/hold.cc kMaxSettlingShare), and asks for a longer hold.
  auto slow = plant;
  slow.R_ohm /= 10.0;
  HoldPlan plan;
  plan.noise_A = 1e-4;
  auto s = MeasureHold(SimulateHold(slow, plan), model::DriverParams{});
  ASSERT_FALSE(s.ok()) << "an unsettled hold read R = " << s->R_ohm << " ohm against " << slow.R_ohm;
  EXPECT_NE(s.status().message().find("still settling"), std::string::npos) << s.status().message();
  // Long enough, it settles and is measured.
  plan.hold_s = 1.0;
  s = MeasureHold(SimulateHold(slow, plan), model::DriverParams{});
  ASSERT_TRUE(s.ok()) << s.status().message();
  EXPECT_NEAR(s->R_ohm / slow.R_ohm, 1.0, 0.01);
}

// The drop-out at the hold's end: the current at the release dip reads the spring's force at the stop against
// the pull per ampere squared. A spring 10 % weaker (stiffness and preload: the force at the stop 10 % less)
// lowers it by about 5 %; shorted turns (N - 3 %) raise it by about 3 %; a winding 5 % more resistive, which
// only makes the current fall faster, moves it by far less. The hold's own R and L are measured as without the
// tail.
TEST(Hold, TheDropOutReadsTheSpringsForceAtTheStop) {
  const auto plant = Valve();
  HoldPlan plan;
  plan.tail_s = 0.05;
  plan.pre_s = 5e-3;
  const RunData run = SimulateHold(plant, plan);
  const auto d = MeasureDropOut(run);
  ASSERT_TRUE(d.ok()) << d.status().message();
  EXPECT_GT(d->rise_A, 10.0 * d->sigma_A);
  EXPECT_GT(d->t_s, 1e-3);
  const auto m = MeasureHold(run, model::DriverParams{});
  ASSERT_TRUE(m.ok()) << m.status().message();
  EXPECT_NEAR(m->R_ohm / plant.R_ohm, 1.0, 0.002);
  EXPECT_LT(d->i_A, m->hold_current_A);

  auto soft = plant;
  soft.k_N_per_m *= 0.9;
  auto turns = plant;
  turns.N_turns *= 0.97;
  auto warm = plant;
  warm.R_ohm *= 1.05;
  const auto ds = MeasureDropOut(SimulateHold(soft, plan));
  const auto dt = MeasureDropOut(SimulateHold(turns, plan));
  const auto dw = MeasureDropOut(SimulateHold(warm, plan));
  ASSERT_TRUE(ds.ok() && dt.ok() && dw.ok());
  const double spring = ds->i_A / d->i_A - 1.0, shorted = dt->i_A / d->i_A - 1.0, winding = dw->i_A / d->i_A - 1.0;
  EXPECT_NEAR(spring, std::sqrt(0.9) - 1.0, 0.015) << "spring " << spring;
  EXPECT_NEAR(shorted, 1.0 / 0.97 - 1.0, 0.015) << "turns " << shorted;
  EXPECT_LT(std::abs(winding), std::abs(spring) / 3.0) << "winding " << winding;
  std::printf("drop-out %.4f A (sigma %.2g) at %.2f ms; spring -10 %%: %+.2f %%, turns -3 %%: %+.2f %%, R +5 %%: %+.2f %%\n",
              d->i_A, d->sigma_A, 1e3 * d->t_s, 100 * spring, 100 * shorted, 100 * winding);

  // Tracked: i_dropout joins the night's values; a tail without a dip (a plunger that does not let go) is a note.
  std::vector<std::string> notes;
  const auto values = HoldValues({run}, model::DriverParams{}, &notes);
  ASSERT_EQ(values.size(), 3u);
  EXPECT_EQ(values[2].name, "i_dropout");
  EXPECT_NEAR(values[2].value, d->i_A, 1e-12);
  auto stuck = plant;
  stuck.k_N_per_m = 0.0, stuck.delta_m = 0.0;  // nothing pulls it back
  RunData held = SimulateHold(stuck, plan);
  const auto none = MeasureDropOut(held);
  ASSERT_FALSE(none.ok());
  EXPECT_NE(none.status().message().find("no release dip"), std::string::npos) << none.status().message();
  EXPECT_EQ(HoldValues({held}, model::DriverParams{}, &notes).size(), 2u);
  ASSERT_EQ(notes.size(), 1u);
  // No tail: nothing asked, nothing said.
  notes.clear();
  EXPECT_EQ(HoldValues({SimulateHold(plant, {})}, model::DriverParams{}, &notes).size(), 2u);
  EXPECT_TRUE(notes.empty());
  EXPECT_FALSE(MeasureDropOut(SimulateHold(plant, {})).ok());
}

// Night by night (gap/track.h): the hold's values join each session's, and the detector flags the winding's
// step on R_hold from the night it happens, and nothing on L_hold; a hold that cannot be measured is a note.
TEST(Hold, TrackedNightByNightAWindingStepIsFlaggedOnRHoldAlone) {
  const auto plant = Valve();
  std::vector<SessionValues> nights;
  constexpr int kNights = 16, kStep = 10;
  for (int n = 0; n < kNights; ++n) {
    auto valve = plant;
    if (n >= kStep) valve.R_ohm *= 1.01;  // a connector inside the winding's leads, or 2.5 K warmer
    HoldPlan plan;
    plan.seed = 100u + static_cast<unsigned>(n);
    SessionValues v;
    v.name = "night" + std::to_string(n + 1);
    v.fit_rmse_A = v.noise_floor_A = 1e-3;
    AddHoldValues(&v, {SimulateHold(valve, plan)}, model::DriverParams{});
    ASSERT_EQ(v.determined.size(), 2u) << v.name;
    auto back = SessionValuesFromJson(SessionValuesJson(v));
    ASSERT_TRUE(back.ok()) << back.status().message();
    nights.push_back(*back);
  }
  RunData broken = SimulateHold(plant, {});
  broken.id = "hold-short";
  broken.gate.resize(broken.gate.size() / 5), broken.i_A.resize(broken.gate.size()),
      broken.t_s.resize(broken.gate.size());
  AddHoldValues(&nights.back(), {broken}, model::DriverParams{});  // cut within its pull-in: not measurable
  const auto t = TrackValues(nights, TrackOptions{});
  ASSERT_TRUE(t.ok()) << t.status().message();
  ASSERT_FALSE(t->flags.empty()) << TrackingReport(*t);
  EXPECT_EQ(t->flags[0].parameter, "R_hold") << TrackingReport(*t);
  EXPECT_EQ(t->flags[0].direction, "up");
  EXPECT_GE(t->flags[0].session_index, kStep);
  EXPECT_LE(t->flags[0].session_index, kStep + 2);
  EXPECT_NEAR(t->flags[0].change_relative, 0.01, 0.002);
  EXPECT_EQ(t->flags[0].since, "night" + std::to_string(kStep + 1));
  for (const auto& f : t->flags) EXPECT_NE(f.parameter, "L_hold") << TrackingReport(*t);
  bool noted = false;
  for (const auto& n : t->notes) noted = noted || n.find("hold run hold-short") != std::string::npos;
  EXPECT_TRUE(noted) << TrackingReport(*t);
}

// The sigmas a hold states are its values' spread over recordings, within a margin (the tracker reads a night's
// deviation against them), and R has no bias beyond that spread: 40 recordings of the server's default hold.
TEST(Hold, ItsSigmasAreTheSpreadOverRecordings) {
  const auto plant = Valve();
  std::vector<double> R, R_sigma, L, L_sigma;
  for (unsigned k = 0; k < 40; ++k) {
    HoldPlan p;
    p.seed = 500 + k, p.hold_s = 0.1, p.noise_A = 2e-3;
    const auto m = MeasureHold(SimulateHold(plant, p), model::DriverParams{});
    ASSERT_TRUE(m.ok()) << m.status().message();
    R.push_back(m->R_ohm), R_sigma.push_back(m->R_sigma_ohm), L.push_back(m->L_H), L_sigma.push_back(m->L_sigma_H);
  }
  const auto mean = [](const std::vector<double>& v) {
    double m = 0.0;
    for (double x : v) m += x;
    return m / static_cast<double>(v.size());
  };
  const auto sd = [&](const std::vector<double>& v) {
    const double m = mean(v);
    double q = 0.0;
    for (double x : v) q += (x - m) * (x - m);
    return std::sqrt(q / static_cast<double>(v.size() - 1));
  };
  // 40 draws know a spread to about 11 %: the bounds leave that on either side of what is measured (R 1.16x, L
  // 1.24x); periods instead of blocks stated R at 2.0x.
  EXPECT_GT(mean(R_sigma) / sd(R), 0.8) << sd(R);
  EXPECT_LT(mean(R_sigma) / sd(R), 1.5) << sd(R);
  EXPECT_GT(mean(L_sigma) / sd(L), 0.8) << sd(L);
  EXPECT_LT(mean(L_sigma) / sd(L), 1.6) << sd(L);
  EXPECT_LT(std::abs(mean(R) - plant.R_ohm), 3.0 * sd(R) / std::sqrt(40.0)) << mean(R);
}

// The switch-on's R flagged while the hold's R_hold, which sees a small fraction of that change, stays: the flag
// says the winding did not change and stands behind the night's other flag (as the independent plant's shorted
// turns, seed 38's bench 5: R -1.1 % and L0 -1.8 % on one night, R_hold still; here larger, so that both flag on
// the same night). Where R_hold moves too, R's flag is plain.
TEST(Hold, AnRFlagTheHoldDoesNotSeeIsNotTheWinding) {
  const auto nights = [](double R_hold_step) {
    std::vector<SessionValues> out;
    std::mt19937 rng(7);
    std::normal_distribution<double> n01;
    for (int n = 0; n < 20; ++n) {
      SessionValues v;
      v.name = "night" + std::to_string(n + 1);
      v.fit_rmse_A = v.noise_floor_A = 1e-3;
      const bool after = n >= 10;
      const auto add = [&](const char* name, double center, double rel_sigma, double step) {
        DeterminedValue d;
        d.name = name;
        d.value = center * (1.0 + rel_sigma * n01(rng) + (after ? step : 0.0));
        d.sigma = d.sigma_white = center * rel_sigma;
        v.determined.push_back(d);
      };
      add("R", 185.0, 0.002, -0.06);   // the switch-on's: 0.2 % a night
      add("L0", 0.136, 0.003, -0.06);  // a smaller z than R's on the same night: the order is the contradiction's
      add("R_hold", 155.0, 0.0003, R_hold_step);
      out.push_back(v);
    }
    return out;
  };
  auto t = TrackValues(nights(0.0), TrackOptions{});
  ASSERT_TRUE(t.ok()) << t.status().message();
  ASSERT_GE(t->flags.size(), 2u) << TrackingReport(*t);
  EXPECT_EQ(t->flags[0].parameter, "L0") << TrackingReport(*t);
  const TrackFlag* r = nullptr;
  for (const auto& f : t->flags) r = f.parameter == "R" ? &f : r;
  ASSERT_NE(r, nullptr) << TrackingReport(*t);
  EXPECT_EQ(r->contradicted_by, "R_hold");
  // On the same night with the larger z, yet behind L0: the order is the contradiction's.
  EXPECT_EQ(r->session_index, t->flags[0].session_index) << TrackingReport(*t);
  EXPECT_GT(std::abs(r->z), std::abs(t->flags[0].z)) << TrackingReport(*t);
  EXPECT_NE(r->meaning.find("not the winding"), std::string::npos) << r->meaning;
  for (const auto& f : t->flags) EXPECT_NE(f.parameter, "R_hold") << TrackingReport(*t);
  // The winding itself 6 % lower: R_hold flags with R, and R's flag is the winding's.
  t = TrackValues(nights(-0.06), TrackOptions{});
  ASSERT_TRUE(t.ok()) << t.status().message();
  for (const auto& f : t->flags) EXPECT_TRUE(f.contradicted_by.empty()) << f.parameter << ": " << f.meaning;
  bool hold_flagged = false;
  for (const auto& f : t->flags) hold_flagged = hold_flagged || f.parameter == "R_hold";
  EXPECT_TRUE(hold_flagged) << TrackingReport(*t);
  // R_hold moving later than R, or by a third of R's change without a flag, still says the winding changed.
  for (const double later : {-0.06, -0.03}) {
    auto late = nights(later);
    for (int n = 10; n < 14; ++n)
      for (auto& d : late[n].determined)
        if (d.name == "R_hold") d.value = 155.0 * (1.0 + 0.0003 * (n % 2 ? 1.0 : -1.0));  // before it moves
    t = TrackValues(late, TrackOptions{});
    ASSERT_TRUE(t.ok()) << t.status().message();
    for (const auto& f : t->flags) EXPECT_TRUE(f.contradicted_by.empty()) << later << " " << TrackingReport(*t);
  }
}

}  // namespace
}  // namespace vb::gap
