#include <gtest/gtest.h>

#include <cmath>

#include "model/plant.h"

namespace vb::model {
namespace {

constexpr double kMu0 = 4e-7 * M_PI;

TEST(Params, Taghizadeh2009MatchesTheNominalContract) {
  auto p = Preset("taghizadeh2009");
  ASSERT_TRUE(p.ok());
  EXPECT_EQ(p->N_turns, 1250);
  EXPECT_EQ(p->A_e_m2, 0.8e-4);
  EXPECT_EQ(p->l_c_m, 0.115);
  EXPECT_EQ(p->mu_r, 120);
  EXPECT_EQ(p->x_t_m, 0.4e-3);
  EXPECT_EQ(p->x_max_m, 0.33e-3);
  EXPECT_EQ(p->R_ohm, 13);
  EXPECT_EQ(p->m_kg, 0.027);
  EXPECT_EQ(p->k_N_per_m, 1e4);
  EXPECT_EQ(p->delta_m, 1.1e-3);
  EXPECT_EQ(p->b_N_s_per_m, 0.2);
  EXPECT_EQ(p->A1_m2, 26.57e-6);
  EXPECT_EQ(p->A2_m2, 35.25e-6);
  EXPECT_TRUE(Validate(*p).ok());
}

TEST(Params, Lunge2013UsesTheDampingOfItsDesignMatrix) {
  auto p = Preset("lunge2013");
  ASSERT_TRUE(p.ok());
  // A22 = -b/M = -357 in the paper's SMC design (seed 002 section IV.A).
  EXPECT_NEAR(p->b_N_s_per_m / p->m_kg, 357.0, 0.5);
  EXPECT_NEAR(p->k_N_per_m / p->m_kg, 25857.0, 1.0);  // A21
  EXPECT_NEAR(p->L_prime_H(), M_PI * 0.008 * kMu0 * 0.006 * 3750.0 * 3750.0 / 0.0012, 1e-12);
  EXPECT_TRUE(Validate(*p).ok());
}

TEST(Params, UnknownPresetAndParameterAreNamed) {
  auto p = Preset("nope");
  ASSERT_FALSE(p.ok());
  EXPECT_NE(p.status().message().find("nope"), std::string::npos);
  PlantParams q = *Preset("taghizadeh2009");
  Status st = SetParam(&q, "Rcoil", 1.0);
  EXPECT_EQ(st.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("Rcoil"), std::string::npos);
  st = SetParam(&q, "R", -3.0);
  EXPECT_NE(st.message().find("R = -3"), std::string::npos);
  EXPECT_EQ(q.R_ohm, 13.0) << "a rejected override must not change the value";
  ASSERT_TRUE(SetParam(&q, "x_max", 0.5e-3).ok());
  st = Validate(q);
  EXPECT_FALSE(st.ok());
  EXPECT_NE(st.message().find("x_t"), std::string::npos);
}

// The co-energy formulation equals the paper's eqs. (7) and (8) for the reluctance law.
TEST(Plant, ReluctanceLawEqualsSeed000Equations) {
  PlantParams p = *Preset("taghizadeh2009");
  Plant plant(p);
  const double K = p.N_turns * p.N_turns * p.A_e_m2 * p.mu_r * kMu0;
  for (double x : {0.0, 0.1e-3, 0.33e-3}) {
    for (double i : {0.1, 0.6, 1.8}) {
      const double L = K / (p.l_c_m + 2 * p.mu_r * (p.x_t_m - x));                       // eq. (4)
      EXPECT_NEAR(plant.L_H(x), L, 1e-15);
      const double Fm = L * L * i * i / (p.N_turns * p.N_turns * p.A_e_m2 * kMu0);        // eq. (8)
      EXPECT_NEAR(plant.MagneticForce_N(i, x), Fm, 1e-12 * Fm);
      const double v = 0.3, V = 24.0;
      const double didt = (V - p.R_ohm * i) / L - 2 * p.mu_r * L * v * i / (p.N_turns * p.N_turns * p.A_e_m2 * p.mu_r * kMu0);  // eq. (7)
      EXPECT_NEAR(plant.CurrentRate_A_per_s(i, x, v, V), didt, 1e-9 * std::abs(didt));
    }
  }
}

TEST(Plant, LimitedTravelForceIsSeed002Equation6) {
  PlantParams p = *Preset("lunge2013");
  Plant plant(p);
  const double Lp = p.L_prime_H(), a = p.a_m;
  for (double x : {0.2e-3, 1e-3, 2e-3}) {
    const double i = 0.03;
    EXPECT_NEAR(plant.MagneticForce_N(i, x), i * i / 2 * a * Lp / ((a + x) * (a + x)), 1e-15);
    EXPECT_NEAR(plant.L_H(x), Lp * x / (x + a), 1e-15);
  }
}

TEST(Plant, BalanceCurrentIsWhereTheSpoolLifts) {
  Plant plant(*Preset("taghizadeh2009"));
  const double i_lift = plant.BalanceCurrent_A(0.0, 4e5);
  // ../shared/perfref: the spool lifts at 0.533710255 A at 4 bar.
  EXPECT_NEAR(i_lift, 0.5337102550, 1e-9);
  EXPECT_NEAR(plant.NetForceAtRest_N(i_lift, 0.0, 4e5), 0.0, 1e-12);
}

}  // namespace
}  // namespace vb::model

#include "model/flow.h"

namespace vb::model {
namespace {

// Eq. (12) is linear in the mean position (the recorder relies on it); choked at 4 bar into atmosphere.
TEST(Flow, Equation12IsLinearInPositionAndChokedAt4Bar) {
  PlantParams p = *Preset("taghizadeh2009");
  const double f1 = MassFlow_kg_per_s(p, 0.1e-3, 4e5), f2 = MassFlow_kg_per_s(p, 0.2e-3, 4e5);
  EXPECT_NEAR(f2, 2 * f1, 1e-15);
  const double choked = 0.0405 * p.C_d * p.C_A_m * 0.1e-3 * (4e5 + p.P_atm_Pa) / std::sqrt(p.T_supply_K);
  EXPECT_NEAR(f1, choked, 1e-15);
  EXPECT_EQ(MassFlow_kg_per_s(p, 0.1e-3, 0.0), 0.0) << "no pressure difference, no flow";
  // Subsonic at a small pressure ratio: less than the choked formula would give.
  const double sub = MassFlow_kg_per_s(p, 0.1e-3, 0.3e5);
  EXPECT_GT(sub, 0.0);
  EXPECT_LT(sub, 0.0405 * p.C_d * p.C_A_m * 0.1e-3 * (0.3e5 + p.P_atm_Pa) / std::sqrt(p.T_supply_K));
}

}  // namespace
}  // namespace vb::model
