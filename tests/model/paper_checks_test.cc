// Checks against what the papers report (seed 000 Figs. 4, 5, 8, 9; seed 003 eqs. 10-11).
#include <gtest/gtest.h>

#include <cmath>

#include "model/simulator.h"
#include "sim_util.h"

namespace vb::model {
namespace {

struct StepResponse {
  double peak_A = 0, peak_t_s = 0, open_t_s = -1, final_A = 0;
};

StepResponse Step(double supply_V, double pressure_Pa) {
  Plant plant(*Preset("taghizadeh2009"));
  Simulator sim(plant, DriverParams{}, Conditions{supply_V, pressure_Pa});
  sim.SetSamplePeriod(1e-6);
  vb::testing::Recording rec;
  sim.SetGate(1);
  sim.AdvanceTo(0.3, &rec);
  StepResponse r;
  for (const auto& e : rec.events)
    if (e.kind == EventKind::kOpen && r.open_t_s < 0) r.open_t_s = e.t_s;
  // The local peak: the last maximum of i before the spool reaches x_max (the back-EMF dip follows it).
  for (const auto& s : rec.samples) {
    if (s.t_s >= r.open_t_s) break;
    if (s.i_A > r.peak_A) {
      r.peak_A = s.i_A;
      r.peak_t_s = s.t_s;
    }
  }
  r.final_A = rec.samples.back().i_A;
  return r;
}

// Seed 000 Fig. 4 and section 4: at 24 V the current shows a local peak of about 0.64 A when the spool starts
// moving and the valve is fully open after about 3.7 ms.
TEST(Seed000, Fig4StepAt24VoltsOpensWithTheBackEmfDip) {
  const StepResponse r = Step(24.0, 4e5);
  EXPECT_GE(r.peak_A, 0.60);
  EXPECT_LE(r.peak_A, 0.68);
  EXPECT_GE(r.open_t_s, 3.4e-3);
  EXPECT_LE(r.open_t_s, 4.2e-3);
  EXPECT_LT(r.peak_t_s, r.open_t_s);
  EXPECT_NEAR(r.final_A, 24.0 / 13.0, 1e-3 * 24.0 / 13.0) << "steady current tends to V/R";
}

// Fig. 5: at 15 V both the peak and the opening come later.
TEST(Seed000, Fig5StepAt15VoltsIsSlower) {
  const StepResponse r24 = Step(24.0, 4e5);
  const StepResponse r15 = Step(15.0, 4e5);
  ASSERT_GT(r15.open_t_s, 0.0) << "the valve must still open at 15 V";
  EXPECT_GT(r15.peak_t_s, r24.peak_t_s);
  EXPECT_GT(r15.open_t_s, r24.open_t_s);
  EXPECT_NEAR(r15.final_A, 15.0 / 13.0, 1e-3 * 15.0 / 13.0);
}

// Seed 003 eqs. (8)-(11): steady-state PWM ripple of an RL coil. The paper's circuit decays through 0 V
// when the switch is off (eq. 3), so the check uses an ideal freewheel (diode_drop_V = 0). "Average" in
// eq. (10) is the mid-range (i_c + i_d)/2, not the time mean.
TEST(Seed003, RlCoilRippleMatchesEquations10And11) {
  Plant plant(*Preset("ts98_coil"));
  DriverParams d;
  d.diode_drop_V = 0.0;
  const double R = 28.5, L = 0.33, V = 24.0, tau = L / R;
  int checked = 0;
  for (double f : {50.0, 100.0, 200.0, 350.0, 500.0, 1000.0}) {
    for (double D : {0.1, 0.3, 0.5, 0.7, 0.9}) {
      Simulator sim(plant, d, Conditions{V, 0.0});
      const double T = 1.0 / f;
      const long periods = static_cast<long>(std::ceil(20.0 * tau / T)) + 1;
      double i_c = 0, i_d = 0;
      for (long n = 0; n < periods; ++n) {
        sim.AdvanceTo(n * T, nullptr);
        i_d = sim.i_A();  // minimum: at the rising edge
        sim.SetGate(1);
        sim.AdvanceTo(n * T + D * T, nullptr);
        i_c = sim.i_A();  // maximum: at the falling edge
        sim.SetGate(0);
      }
      const double a = std::exp(-D * T / tau), b = std::exp(-(1 - D) * T / tau);
      const double ic = V / R * (1 - a) / (1 - a * b);   // eq. (8)
      const double id = ic * b;                          // eq. (9)
      const double avg = (ic + id) / 2, amp = ic - id;   // eqs. (10), (11)
      EXPECT_NEAR((i_c + i_d) / 2, avg, 0.01 * avg) << "f " << f << " D " << D;
      EXPECT_NEAR(i_c - i_d, amp, 0.01 * amp) << "f " << f << " D " << D;
      ++checked;
    }
  }
  EXPECT_EQ(checked, 30);
}

// Moving-average spool position at steady state, in % of x_max (seed 000 section 5).
double MeanPositionPct(double duty, double frequency_Hz, double pressure_Pa) {
  Plant plant(*Preset("taghizadeh2009"));
  Simulator sim(plant, DriverParams{}, Conditions{24.0, pressure_Pa});
  const double T = 1.0 / frequency_Hz;
  sim.SetSamplePeriod(T / 200.0);
  vb::testing::Recording rec;
  vb::testing::RunPwm(sim, frequency_Hz, duty, 0.3, &rec);
  double sum = 0;
  int n = 0;
  for (const auto& s : rec.samples)
    if (s.t_s >= 0.2 && s.t_s < 0.3) {
      sum += s.x_m;
      ++n;
    }
  return 100.0 * sum / n / 0.33e-3;
}

TEST(Seed000, Fig8StaticMapIsMonotoneWithDeadBandAndSaturation) {
  std::vector<double> map;
  for (double D = 0.0; D <= 1.0001; D += 0.05) map.push_back(MeanPositionPct(D, 50.0, 4e5));
  for (size_t k = 1; k < map.size(); ++k) EXPECT_GE(map[k], map[k - 1] - 1e-9) << "duty " << 0.05 * k;
  EXPECT_EQ(map[1], 0.0) << "dead band: 5 % duty does not open the valve";
  EXPECT_GT(map.back(), 99.9) << "saturated at 100 % duty";
  EXPECT_GT(map[map.size() - 2], 80.0) << "saturation region near full duty";
}

TEST(Seed000, Fig8HigherSupplyPressureLowersTheAveragePosition) {
  // (A1 - A2) < 0: supply pressure pushes the spool closed.
  const double d = 0.4;
  const double p0 = MeanPositionPct(d, 50.0, 0.0), p4 = MeanPositionPct(d, 50.0, 4e5),
               p6 = MeanPositionPct(d, 50.0, 6e5);
  EXPECT_GT(p0, p4);
  EXPECT_GT(p4, p6);
}

// Effective duty range: from the last duty with x_avg below 5 % to the first above 95 %.
double EffectiveRange(double frequency_Hz) {
  double lo = -1, hi = -1;
  for (double D = 0.0; D <= 1.0001; D += 0.025) {
    const double p = MeanPositionPct(D, frequency_Hz, 4e5);
    if (p < 5.0) lo = D;
    if (p > 95.0 && hi < 0) hi = D;
  }
  return hi - lo;
}

TEST(Seed000, Fig9HigherPwmFrequencyNarrowsTheEffectiveDutyRange) {
  const double r50 = EffectiveRange(50.0), r100 = EffectiveRange(100.0);
  EXPECT_GT(r50, 0.0);
  EXPECT_LT(r100, r50);
}

}  // namespace
}  // namespace vb::model
