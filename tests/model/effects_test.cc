// Each coil-side effect changes what it should, and only that (issue 5: "each effect in the emulator changes
// what it should").
#include <gtest/gtest.h>

#include <cmath>

#include "model/simulator.h"
#include "sim_util.h"

namespace vb::model {
namespace {

PlantParams WithEffect(const char* preset, const char* name, std::vector<std::pair<std::string, double>> params) {
  PlantParams p = *Preset(preset);
  Status st = AddEffect(&p.effects, name, params);
  EXPECT_TRUE(st.ok()) << st.message();
  return p;
}

// A step on the plain RL coil (no moving part) for `t_s`; returns the final measured current and the sim.
double StepCurrent(const PlantParams& p, double t_s, Simulator** keep = nullptr) {
  static Plant* plant = nullptr;
  delete plant;
  plant = new Plant(p);
  auto* sim = new Simulator(*plant, DriverParams{}, Conditions{24.0, 0.0});
  sim->SetGate(1);
  sim->AdvanceTo(t_s, nullptr);
  const double i = sim->measured_current_A();
  if (keep != nullptr) {
    *keep = sim;
  } else {
    delete sim;
  }
  return i;
}

// Every name a fit reports has its unit: plant parameters, every effect's parameters, and the fit's
// reparametrisation coulomb_friction.F_s_excess (a force: the diagnosis page printed it without a unit).
TEST(Effects, EveryFittedNameHasItsUnit) {
  EXPECT_EQ(ParamUnit("R"), "ohm");
  EXPECT_EQ(ParamUnit("coulomb_friction.F_s_excess"), "N");
  EXPECT_EQ(ParamUnit("coulomb_friction.F_c"), "N");
  for (const auto& p : ParamTable()) EXPECT_FALSE(ParamUnit(p.name).empty()) << p.name;
  for (const auto& e : EffectCatalog())
    for (const auto& q : e.params) EXPECT_EQ(ParamUnit(std::string(e.name) + "." + std::string(q.name)), q.unit) << e.name;
  EXPECT_EQ(ParamUnit("no_such.thing"), "");
  EXPECT_EQ(ParamUnit("coulomb_friction._excess"), "");
}

TEST(Effects, CatalogNamesAndErrors) {
  const auto names = EffectNames();
  for (const char* n : {"none", "coil_heating", "magnetic_saturation", "eddy_currents", "residual_magnetism",
                        "coulomb_friction", "end_stop_bounce", "supply_resistance", "sensor_lag"})
    EXPECT_NE(std::find(names.begin(), names.end(), n), names.end()) << n;
  Effects fx;
  EXPECT_NE(AddEffect(&fx, "gremlins", {}).message().find("unknown effect"), std::string::npos);
  EXPECT_NE(AddEffect(&fx, "supply_resistance", {{"R_x", 1.0}}).message().find("params[R_x]"), std::string::npos);
  EXPECT_NE(AddEffect(&fx, "supply_resistance", {{"R_s", -1.0}}).message().find("outside"), std::string::npos);
  for (const auto& e : EffectCatalog()) EXPECT_TRUE(e.simulated) << e.name;
  EXPECT_FALSE(fx.any()) << "a rejected effect changes nothing";
}

// Supply resistance: the steady current is V / (R + R_s); the time constant L / (R + R_s); the freewheel decay
// (diode loop) does not see R_s.
TEST(Effects, SupplyResistanceSagsTheOnStateOnly) {
  const PlantParams p = WithEffect("ts98_coil", "supply_resistance", {{"R_s", 1.5}});
  EXPECT_NEAR(StepCurrent(p, 0.5), 24.0 / 30.0, 1e-9);
  // The time constant with R_s: i(tau) = (1 - 1/e) of the final value.
  const double tau = 0.33 / 30.0;
  EXPECT_NEAR(StepCurrent(p, tau), 24.0 / 30.0 * (1.0 - std::exp(-1.0)), 1e-9);
}

// Supply voltage: the coil is driven by gain x the declared supply: the current of a step is that of the declared
// supply scaled by the gain (a linear coil), and on a moving valve the pull (i^2) follows the current, so the
// plunger lifts later at a lower gain: a sensor gain would scale the reading and leave the lift where it was.
TEST(Effects, SupplyVoltageScalesTheCurrentItself) {
  const PlantParams p = WithEffect("ts98_coil", "supply_voltage", {{"gain", 0.8}});
  const double tau = 0.33 / 28.5;
  EXPECT_NEAR(StepCurrent(p, tau), 0.8 * 24.0 / 28.5 * (1.0 - std::exp(-1.0)), 1e-9);
  EXPECT_NEAR(StepCurrent(p, 0.5), 0.8 * 24.0 / 28.5, 1e-9);
  auto lift_s = [](const PlantParams& pp) -> double {
    Plant plant(pp);
    Simulator sim(plant, DriverParams{}, Conditions{24.0, 0.0});
    vb::testing::Recording rec;
    sim.SetGate(1);
    sim.AdvanceTo(0.05, &rec);
    for (const auto& e : rec.events)
      if (e.kind == EventKind::kLift) return e.t_s;
    return INFINITY;
  };
  const PlantParams moving = *Preset(kDefaultPreset);
  PlantParams low = moving;
  ASSERT_TRUE(AddEffect(&low.effects, "supply_voltage", {{"gain", 0.85}}).ok());
  const double nominal = lift_s(moving), later = lift_s(low);
  ASSERT_TRUE(std::isfinite(nominal));
  EXPECT_GT(later, nominal * 1.05) << "a lower supply lifts the plunger later";
}

// Driver delay: the coil sees each gate edge delay_s late, so a switch-on's current is the nominal one shifted by
// the delay; the recorded gate and its statistics are the command's.
TEST(Effects, DriverDelayShiftsTheCoilsEdgesNotTheCommand) {
  const PlantParams late = WithEffect("ts98_coil", "driver_delay", {{"delay_s", 200e-6}});
  auto run = [](const PlantParams& pp, vb::testing::Recording* rec) {
    Plant plant(pp);
    Simulator sim(plant, DriverParams{}, Conditions{24.0, 0.0});
    sim.SetSamplePeriod(1e-5);
    sim.SetGate(1);
    sim.AdvanceTo(2e-3, rec);
    sim.SetGate(0);
    EXPECT_EQ(sim.gate(), 0) << "gate() is the command";
    sim.AdvanceTo(6e-3, rec);
    sim.EmitPendingSample(rec);
  };
  vb::testing::Recording nominal, delayed;
  run(*Preset("ts98_coil"), &nominal);
  run(late, &delayed);
  ASSERT_EQ(nominal.samples.size(), delayed.samples.size());
  // 200 us = 20 samples: sample k of the delayed run is sample k - 20 of the nominal one.
  for (std::size_t k = 0; k < delayed.samples.size(); ++k) {
    const double expect = k < 20 ? 0.0 : nominal.samples[k - 20].i_A;
    ASSERT_NEAR(delayed.samples[k].i_A, expect, 1e-9) << "sample " << k;
    EXPECT_EQ(delayed.samples[k].gate, nominal.samples[k].gate) << "the recorded gate is the command";
  }
  EXPECT_GT(nominal.samples[20].i_A, 0.01);
  // More edges within the delay than the driver holds: a clear failure, not a lost edge.
  PlantParams slow = WithEffect("ts98_coil", "driver_delay", {{"delay_s", 5e-3}});
  Plant plant(slow);
  Simulator sim(plant, DriverParams{}, Conditions{24.0, 0.0});
  for (int n = 0; n < 70; ++n) {
    sim.AdvanceTo(n * 2e-5, nullptr);
    sim.SetGate(n % 2 == 0 ? 1 : 0);
  }
  ASSERT_NE(sim.failure(), nullptr);
  EXPECT_NE(std::string(sim.failure()).find("driver_delay"), std::string::npos) << sim.failure();
}

// Coil heating: R rises with temperature, so the steady current falls below V/R and keeps falling; the
// temperature rise tends to the thermal equilibrium of the I^2 R losses.
TEST(Effects, CoilHeatingLowersTheCurrentAsTheCoilWarms) {
  const PlantParams p =
      WithEffect("ts98_coil", "coil_heating", {{"alpha", 3.93e-3}, {"R_th", 2.0}, {"C_th", 0.6}, {"dT0", 0.0}});
  Simulator* sim = nullptr;
  const double i_early = StepCurrent(p, 0.1, &sim);
  sim->AdvanceTo(8.0, nullptr);  // ~6.7 thermal time constants
  const double i_late = sim->measured_current_A();
  EXPECT_LT(i_early, 24.0 / 28.5);
  EXPECT_LT(i_late, i_early - 0.02);
  // Equilibrium: dT = R_th i^2 R (1 + alpha dT) and i = V / (R (1 + alpha dT)).
  const double dT = sim->coil_temperature_rise_K();
  const double R_hot = 28.5 * (1.0 + 3.93e-3 * dT);
  EXPECT_NEAR(i_late, 24.0 / R_hot, 1e-6);
  EXPECT_NEAR(dT, 2.0 * i_late * i_late * R_hot, 0.02 * dT);
  delete sim;
}

// Sensor lag: the measured current is the true one through a first-order lag (and a latency); the steady
// value is unchanged. The chain works on samples: here at 1 us.
double SampledStep(const PlantParams& p, double t_s) {
  Plant plant(p);
  Simulator sim(plant, DriverParams{}, Conditions{24.0, 0.0});
  sim.SetSamplePeriod(1e-6);
  vb::testing::Recording rec;
  sim.SetGate(1);
  sim.AdvanceTo(t_s, &rec);
  sim.EmitPendingSample(&rec);
  EXPECT_NEAR(rec.samples.back().i_A, sim.measured_current_A(), 1e-15) << "controllers see the latest reading";
  return rec.samples.back().i_A;
}

TEST(Effects, SensorLagDelaysTheMeasuredStepOnly) {
  const PlantParams lagged = WithEffect("ts98_coil", "sensor_lag", {{"tau_s", 2e-3}});
  // True current: (V/R)(1 - e^{-t/T}), T = L/R; lagged through tau: the standard two-pole step response.
  const double T = 0.33 / 28.5, tau = 2e-3, t = 3e-3, I = 24.0 / 28.5;
  auto two_pole = [&](double tt) { return I * (1.0 - (T * std::exp(-tt / T) - tau * std::exp(-tt / tau)) / (T - tau)); };
  EXPECT_NEAR(SampledStep(lagged, t), two_pole(t), 1e-7);
  EXPECT_GT(SampledStep(*Preset("ts98_coil"), t), two_pole(t) + 0.01);
  EXPECT_NEAR(SampledStep(lagged, 0.5), I, 1e-7);
  // Latency: the same reading delay_s later (0 before the run started).
  const PlantParams late = WithEffect("ts98_coil", "sensor_lag", {{"tau_s", 2e-3}, {"delay_s", 80e-6}});
  EXPECT_NEAR(SampledStep(late, t), two_pole(t - 80e-6), 1e-7);
  EXPECT_NEAR(SampledStep(late, 50e-6), 0.0, 1e-12);
}

// Eddy currents: the terminal current jumps by V / R_p at the edge (the loss branch), the magnetising current
// (the force) rises more slowly than without the branch, and the valve opens later.
TEST(Effects, EddyCurrentsDelayTheForceAndStepTheTerminalCurrent) {
  PlantParams eddy = WithEffect("taghizadeh2009", "eddy_currents", {{"R_p", 400.0}});
  Plant pe(eddy), pn(*Preset("taghizadeh2009"));
  Simulator se(pe, DriverParams{}, Conditions{24.0, 4e5}), sn(pn, DriverParams{}, Conditions{24.0, 4e5});
  vb::testing::Recording re, rn;
  se.SetSamplePeriod(1e-6);
  se.SetGate(1);
  se.AdvanceTo(0.02, &re);
  sn.SetGate(1);
  sn.AdvanceTo(0.02, &rn);
  ASSERT_GT(re.samples.size(), 10u);
  // Just after the edge: i = V / (R + R_p) through the branch, while the inductance has barely started.
  EXPECT_NEAR(re.samples[1].i_A, 24.0 / (13.0 + 400.0), 2e-3);
  double open_e = -1, open_n = -1;
  for (const auto& e : re.events)
    if (e.kind == EventKind::kOpen && open_e < 0) open_e = e.t_s;
  for (const auto& e : rn.events)
    if (e.kind == EventKind::kOpen && open_n < 0) open_n = e.t_s;
  ASSERT_GT(open_e, 0);
  EXPECT_GT(open_e, open_n + 50e-6) << "the force lags: the valve opens later";
  // At steady state (20 coil time constants) the branch carries nothing: the nominal coil's current.
  se.AdvanceTo(0.25, nullptr);
  sn.AdvanceTo(0.25, nullptr);
  EXPECT_NEAR(se.measured_current_A(), sn.measured_current_A(), 1e-6);
  EXPECT_NEAR(se.measured_current_A(), 24.0 / 13.0, 1e-6);
}

// With no effect, nothing changes: the nominal path is bit-for-bit the same.
TEST(Effects, NoEffectIsTheNominalModel) {
  Effects none;
  EXPECT_FALSE(none.any());
  EXPECT_FALSE(none.NeedsGeneralPath());
}

}  // namespace
}  // namespace vb::model

namespace vb::model {
namespace {

// The saturated force is the co-energy derivative: compare with a finite difference of W'(i, x) = int lambda di
// integrated numerically (Simpson), at currents from linear to deep saturation.
TEST(Effects, SaturatedForceIsTheCoEnergyDerivative) {
  for (const double tanh_knee : {0.0, 1.0, 2.0}) {  // Frohlich's knee, the tanh knee and the arctan knee
    SCOPED_TRACE(tanh_knee > 1.5 ? "arctan" : tanh_knee > 0.5 ? "tanh" : "Frohlich");
    PlantParams p = WithEffect("taghizadeh2009", "magnetic_saturation", {{"B_sat", 1.5}, {"tanh", tanh_knee}});
    Plant plant(p);
    Simulator sim(plant, DriverParams{}, Conditions{24.0, 0.0});
    const double ls = p.N_turns * p.A_e_m2 * 1.5;
    const double air = 1.0 / p.mu_r;  // the air path's share of L (docs/model.md)
    auto knee = [&](double u) {
      return tanh_knee > 1.5 ? 2.0 / M_PI * std::atan(0.5 * M_PI * u) : tanh_knee > 0.5 ? std::tanh(u) : u / (1.0 + std::abs(u));
    };
    auto lambda = [&](double i, double x) {
      const double L = plant.L_H(x);
      return ls * knee((1.0 - air) * L * i / ls) + air * L * i;
    };
    auto coenergy = [&](double i, double x) {
      const int n = 2000;  // Simpson on [0, i]
      double s = lambda(0, x) + lambda(i, x);
      for (int k = 1; k < n; ++k) s += (k % 2 ? 4.0 : 2.0) * lambda(i * k / n, x);
      return s * i / (3.0 * n);
    };
    for (double i : {0.2, 0.8, 1.8, 3.0}) {
      for (double x : {0.0, 0.2e-3, 0.33e-3}) {
        const double h = 1e-7;
        const double fd = (coenergy(i, x + h) - coenergy(i, x - h)) / (2 * h);
        EXPECT_NEAR(sim.MagneticsAt(i, x).force_N, fd, 1e-6 * std::max(1.0, std::abs(fd))) << i << " A, " << x << " m";
        // and the flux slope the coil law uses
        const double di = 1e-6;
        EXPECT_NEAR(sim.MagneticsAt(i, x).dlambda_di, (lambda(i + di, x) - lambda(i - di, x)) / (2 * di), 1e-6);
      }
    }
    // Small currents: the linear law.
    Plant nominal(*Preset("taghizadeh2009"));
    EXPECT_NEAR(sim.MagneticsAt(0.001, 0.0).force_N, nominal.MagneticForce_N(0.001, 0.0), 1e-6);
  }
}

// Form 3, the core in series with the gaps (model/coil.h): lambda(i, x) solved here independently (bisection on
// the core's field), the force checked against a finite difference of the co-energy and the incremental
// inductance against one of lambda; at small currents the linear law; and the saturation depends on the gap:
// closed, the core takes the magnetomotive force and saturates hard, open, the gap takes it.
TEST(Effects, SeriesCoreSaturationIsTheCoEnergyDerivativeAndDependsOnTheGap) {
  PlantParams p = WithEffect("taghizadeh2009", "magnetic_saturation", {{"B_sat", 1.5}, {"tanh", 3.0}});
  Plant plant(p);
  Simulator sim(plant, DriverParams{}, Conditions{24.0, 0.0});
  const double mu0 = 4e-7 * M_PI, N = p.N_turns, A = p.A_e_m2, lc = p.l_c_m, B_s = 1.5;
  const double Hk = B_s / (mu0 * (p.mu_r - 1.0));
  auto lambda = [&](double i, double x) {
    const double Rg = N * N / plant.L_H(x) - lc / (mu0 * p.mu_r * A);
    auto B = [&](double H) { return B_s * (H / Hk) / (1.0 + std::abs(H / Hk)) + mu0 * H; };
    double lo = -1e9, hi = 1e9;  // N i = lc H + A B(H) Rg, increasing in H
    for (int k = 0; k < 200; ++k) {
      const double mid = 0.5 * (lo + hi);
      (lc * mid + A * B(mid) * Rg < N * i ? lo : hi) = mid;
    }
    return N * A * B(0.5 * (lo + hi));
  };
  auto coenergy = [&](double i, double x) {
    const int n = 400;
    double s = lambda(0, x) + lambda(i, x);
    for (int k = 1; k < n; ++k) s += (k % 2 ? 4.0 : 2.0) * lambda(i * k / n, x);
    return s * i / (3.0 * n);
  };
  for (double i : {0.2, 0.8, 1.8, -1.8}) {
    for (double x : {0.0, 0.2e-3, 0.33e-3}) {
      const double h = 1e-6;
      const double fd = (coenergy(i, x + h) - coenergy(i, x - h)) / (2 * h);
      EXPECT_NEAR(sim.MagneticsAt(i, x).force_N, fd, 1e-4 * std::max(1.0, std::abs(fd))) << i << " A, " << x << " m";
      const double di = 1e-5;
      const double L_fd = (lambda(i + di, x) - lambda(i - di, x)) / (2 * di);
      EXPECT_NEAR(sim.MagneticsAt(i, x).dlambda_di, L_fd, 1e-5 * plant.L_H(x)) << i << " A, " << x << " m";
      const double dx = 1e-8;
      EXPECT_NEAR(sim.MagneticsAt(i, x).dlambda_dx, (lambda(i, x + dx) - lambda(i, x - dx)) / (2 * dx),
                  1e-4 * std::max(1.0, std::abs(sim.MagneticsAt(i, x).dlambda_dx)))
          << i << " A, " << x << " m";
    }
  }
  Plant nominal(*Preset("taghizadeh2009"));
  EXPECT_NEAR(sim.MagneticsAt(1e-5, 0.0).force_N, nominal.MagneticForce_N(1e-5, 0.0), 1e-9);
  EXPECT_NEAR(sim.MagneticsAt(1e-5, 0.33e-3).dlambda_di, nominal.L_H(0.33e-3), 1e-4 * nominal.L_H(0.33e-3));
  // Deep in saturation the core is as if it were air: the incremental inductance tends to N^2 / (l_c / (mu0 A_e)
  // + R_g(x)), which depends on the gap (the parallel forms tend to L(x) / mu_r instead).
  for (double x : {0.0, 0.33e-3}) {
    const double Rg = N * N / plant.L_H(x) - lc / (mu0 * p.mu_r * A);
    const double air_core = N * N / (lc / (mu0 * A) + Rg);
    EXPECT_NEAR(sim.MagneticsAt(1e4, x).dlambda_di, air_core, 0.01 * air_core) << x << " m";
    EXPECT_GT(air_core, 1.1 * plant.L_H(x) / p.mu_r) << x << " m";  // 1.14 closed, 1.82 open here
  }
  // At 1.8 A the pulled-in (narrow-gap) core has lost more of its incremental inductance than the open one.
  const double open = sim.MagneticsAt(1.8, 0.0).dlambda_di / nominal.L_H(0.0);
  const double closed = sim.MagneticsAt(1.8, 0.33e-3).dlambda_di / nominal.L_H(0.33e-3);
  EXPECT_LT(closed, open) << open << " " << closed;
}

// Saturation weakens the pull at high current and lowers the incremental inductance; the steady current is
// still V/R (the resistance is unchanged). (Whether the valve opens later depends on the degree: mild
// saturation lets the current rise faster, which can outweigh the slightly weaker pull at the lift current.)
TEST(Effects, SaturationWeakensThePullAndSpeedsTheRise) {
  PlantParams sat = WithEffect("taghizadeh2009", "magnetic_saturation", {{"B_sat", 3.0}});
  Plant ps(sat), pn(*Preset("taghizadeh2009"));
  Simulator ss(ps, DriverParams{}, Conditions{24.0, 4e5}), sn(pn, DriverParams{}, Conditions{24.0, 4e5});
  vb::testing::Recording rs, rn;
  ss.SetGate(1);
  ss.AdvanceTo(0.3, &rs);
  sn.SetGate(1);
  sn.AdvanceTo(0.3, &rn);
  EXPECT_NEAR(ss.measured_current_A(), 24.0 / 13.0, 1e-6);
  EXPECT_LT(ss.MagneticsAt(1.8, 0.33e-3).force_N, 0.8 * pn.MagneticForce_N(1.8, 0.33e-3));
  EXPECT_LT(ss.MagneticsAt(1.8, 0.33e-3).dlambda_di, 0.6 * pn.L_H(0.33e-3));
  // The energised current reaches 90 % of V/R sooner than the nominal coil's.
  auto t90 = [](const vb::testing::Recording& r) {
    for (const auto& s : r.samples)
      if (s.i_A >= 0.9 * 24.0 / 13.0) return s.t_s;
    return 1.0;
  };
  ss.Reset();
  sn.Reset();
  rs.samples.clear();
  rn.samples.clear();
  ss.SetSamplePeriod(1e-5);
  sn.SetSamplePeriod(1e-5);
  ss.SetGate(1);
  ss.AdvanceTo(0.1, &rs);
  sn.SetGate(1);
  sn.AdvanceTo(0.1, &rn);
  EXPECT_LT(t90(rs), 0.8 * t90(rn));
}

}  // namespace
}  // namespace vb::model

namespace vb::model {
namespace {

// End-stop bounce: the spool hits x_max several times with decreasing rebound, then rests; each impact
// dents the current (back-EMF reverses with the velocity). Nominal: exactly one impact.
TEST(Effects, EndStopBounceReboundsAndSettles) {
  auto impacts = [](const PlantParams& p) {
    Plant plant(p);
    Simulator sim(plant, DriverParams{}, Conditions{24.0, 4e5});
    vb::testing::Recording rec;
    sim.SetGate(1);
    sim.AdvanceTo(0.02, &rec);
    int opens = 0;
    for (const auto& e : rec.events) opens += e.kind == EventKind::kOpen;
    EXPECT_EQ(sim.contact(), Contact::kUpper) << "settles at the stop";
    return opens;
  };
  EXPECT_EQ(impacts(*Preset("taghizadeh2009")), 1);
  const int e5 = impacts(WithEffect("taghizadeh2009", "end_stop_bounce", {{"e", 0.5}}));
  const int e8 = impacts(WithEffect("taghizadeh2009", "end_stop_bounce", {{"e", 0.8}}));
  EXPECT_GE(e5, 2);
  EXPECT_GT(e8, e5) << "a livelier stop bounces more often before it settles";
}

}  // namespace
}  // namespace vb::model

namespace vb::model {
namespace {

// Coulomb friction: breaking away from the lower stop needs the static force on top of the spring and
// pressure, so the spool lifts later, at a higher current, and the valve opens later. (The stroke itself can be
// shorter: the spool breaks away with F_s of extra pull and only F_c < F_s opposes it while it moves.)
TEST(Effects, FrictionDelaysTheLiftAndTheStroke) {
  auto first = [](const PlantParams& p, EventKind kind) {
    Plant plant(p);
    Simulator sim(plant, DriverParams{}, Conditions{24.0, 4e5});
    vb::testing::Recording rec;
    sim.SetGate(1);
    sim.AdvanceTo(0.02, &rec);
    for (const auto& e : rec.events)
      if (e.kind == kind) return std::make_pair(e.t_s, e.i_A);
    return std::make_pair(-1.0, 0.0);
  };
  const PlantParams fr = WithEffect("taghizadeh2009", "coulomb_friction", {{"F_c", 2.0}, {"F_s", 3.0}});
  const auto lift_n = first(*Preset("taghizadeh2009"), EventKind::kLift);
  const auto lift_f = first(fr, EventKind::kLift);
  ASSERT_GT(lift_f.first, 0.0);
  EXPECT_GT(lift_f.first, lift_n.first);
  // The lift current solves F_m(i) = k delta - (A1 - A2) P + F_s.
  Plant plant(*Preset("taghizadeh2009"));
  const double need = -plant.PassiveForce_N(0.0, 4e5) + 3.0;
  EXPECT_NEAR(plant.MagneticForce_N(lift_f.second, 0.0), need, 1e-6 * need);
  const auto open_n = first(*Preset("taghizadeh2009"), EventKind::kOpen);
  const auto open_f = first(fr, EventKind::kOpen);
  EXPECT_GT(open_f.first, open_n.first) << "the valve opens later";
}

// A short pulse lifts the spool; after the pulse it decelerates and static friction can hold it mid-travel:
// "stick" events with the spool at rest strictly between the stops.
TEST(Effects, StaticFrictionHoldsTheSpoolMidTravel) {
  const PlantParams fr = WithEffect("taghizadeh2009", "coulomb_friction", {{"F_c", 4.0}, {"F_s", 6.0}});
  Plant plant(fr);
  Simulator sim(plant, DriverParams{}, Conditions{24.0, 0.0});
  vb::testing::Recording rec;
  bool stuck_mid = false;
  for (int n = 0; n < 20 && !stuck_mid; ++n) {  // 200 Hz PWM at 35 %: the spool never settles at a stop
    sim.SetGate(1);
    sim.AdvanceTo(n * 5e-3 + 1.75e-3, &rec);
    sim.SetGate(0);
    sim.AdvanceTo((n + 1) * 5e-3, &rec);
    for (const auto& e : rec.events)
      if (e.kind == EventKind::kStick && e.x_m > 1e-6 && e.x_m < 0.33e-3 - 1e-6) stuck_mid = true;
  }
  EXPECT_TRUE(stuck_mid);
  Effects bad;
  EXPECT_NE(AddEffect(&bad, "coulomb_friction", {{"F_c", 3.0}, {"F_s", 2.0}}).message().find("F_s"), std::string::npos);
}

}  // namespace
}  // namespace vb::model

namespace vb::model {
namespace {

// Residual magnetism: the remanent flux delays the release after de-energising, and the lift needs more
// current (the play lags the rising current); the steady energised current is unchanged (V/R).
TEST(Effects, ResidualMagnetismDelaysReleaseAndLift) {
  auto times = [](const PlantParams& p) {
    Plant plant(p);
    Simulator sim(plant, DriverParams{}, Conditions{24.0, 4e5});
    vb::testing::Recording rec;
    sim.SetGate(1);
    sim.AdvanceTo(0.05, &rec);
    const double i_on = sim.measured_current_A();
    sim.SetGate(0);
    sim.AdvanceTo(0.1, &rec);
    double lift = -1, release = -1, lift_i = 0;
    for (const auto& e : rec.events) {
      if (e.kind == EventKind::kLift && lift < 0) {
        lift = e.t_s;
        lift_i = e.i_A;
      }
      if (e.kind == EventKind::kRelease && release < 0) release = e.t_s;
    }
    struct R {
      double lift, lift_i, release, i_on;
    };
    return R{lift, lift_i, release, i_on};
  };
  const auto n = times(*Preset("taghizadeh2009"));
  const auto r = times(WithEffect("taghizadeh2009", "residual_magnetism", {{"w", 0.08}, {"alpha", 0.35}}));
  ASSERT_GT(r.lift, 0.0);
  ASSERT_GT(r.release, 0.0);
  EXPECT_GT(r.release, n.release) << "remanent flux holds the spool longer";
  EXPECT_GT(r.lift_i, n.lift_i + 0.02) << "the lift needs (1 - alpha) w more current";
  EXPECT_NEAR(r.i_on, n.i_on, 5e-3) << "energised, the coil current follows the nominal one";
}

}  // namespace
}  // namespace vb::model
