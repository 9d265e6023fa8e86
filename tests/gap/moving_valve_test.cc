// Moving valves from their switch-on current (issue 25, docs/real-data.md "Moving valves"): identification from
// scratch, prediction across pressures and supplies, and "what changed" against a reference identified from
// scratch. On practice3 (../shared/gapbench/practice3, skipped when missing) and on synthetic valves made here
// with other parameters (gap/switch_on_synth.h: our model through the scope chain of practice3).
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <unistd.h>

#include "gap/dataset.h"
#include "gap/diagnose.h"
#include "gap/moving_valve.h"
#include "gap/predict.h"
#include "gap/scope_csv.h"
#include "gap/switch_on_synth.h"
#include "model/params.h"

namespace vb::gap {
namespace {

namespace fs = std::filesystem;

const fs::path kPractice3 = fs::path(VB_SHARED_DIR) / "gapbench" / "practice3";

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

model::PlantParams Family() { return *model::Preset("taghizadeh2009"); }

// A verdict names the change when it contains one of the label's accept words.
bool Accepted(const std::string& verdict, const nlohmann::json& accept) {
  for (const auto& w : accept)
    if (Lower(verdict).find(Lower(w.get<std::string>())) != std::string::npos) return true;
  return false;
}

// scratch_evaluations > 0: the reference's identification gets that many evaluations (a small count leaves it
// unidentified, as a valve outside the family would); scratch_ode_steps >= 0: its step budget.
Diagnosis DiagnoseAgainst(const std::string& target_dir, const std::string& reference_dir, int scratch_evaluations = 0,
                          std::int64_t scratch_ode_steps = -1) {
  auto target = LoadDataset(target_dir, model::PresetNames());
  auto reference = LoadDataset(reference_dir, model::PresetNames());
  EXPECT_TRUE(target.ok()) << target.status().message();
  EXPECT_TRUE(reference.ok()) << reference.status().message();
  DiagnoseOptions o;
  o.reference = &*reference;  // no reference_fit params: identified from scratch
  if (scratch_evaluations > 0) o.reference_fit.scratch_max_evaluations = scratch_evaluations;
  o.reference_fit.scratch_max_ode_steps = scratch_ode_steps;
  auto d = Diagnose(*target, Family(), o);
  EXPECT_TRUE(d.ok()) << d.status().message();
  return d.ok() ? *d : Diagnosis{};
}

// ---- practice3 ------------------------------------------------------------------------------------------------

TEST(MovingValvePractice3, M01IdentifiedFromScratchPredictsSixBarAndLowSupply) {
  if (!fs::is_directory(kPractice3 / "m01")) GTEST_SKIP() << kPractice3 << " is missing";
  auto ds = LoadDataset((kPractice3 / "m01").string(), model::PresetNames());
  ASSERT_TRUE(ds.ok()) << ds.status().message();
  auto id = IdentifyMovingValve(*ds, Family());
  ASSERT_TRUE(id.ok()) << id.status().message();
  // The issue's target: each holdout run within 5 mA RMS.
  int holdouts = 0;
  for (const auto& r : id->landmarks) {
    if (r.split != Split::kHoldout) continue;
    ++holdouts;
    EXPECT_LT(r.rmse_A, 5e-3) << r.run;
    EXPECT_EQ(r.measured.pulls_in, r.predicted.pulls_in) << r.run;
    if (r.supply_V < 10.0) {
      EXPECT_FALSE(r.predicted.pulls_in) << r.run << ": 0.75x supply does not pull in";
    }
    if (r.measured.pulls_in && r.predicted.pulls_in) {
      EXPECT_NEAR(r.predicted.pull_in_s, r.measured.pull_in_s, 2e-4) << r.run;
    }
  }
  EXPECT_EQ(holdouts, 2);
  EXPECT_LT(id->holdout_rmse_after_A, 5e-3);
  // The identifiability report names the held stroke and what it determines.
  const std::string json = MovingIdentificationJson(*id);
  EXPECT_NE(json.find("\"holdout_rmse_after_A\""), std::string::npos);
  EXPECT_NE(json.find("m*x_max^2"), std::string::npos);
  EXPECT_NE(json.find("\"x_max\""), std::string::npos);
  // About 37 ohm (README): the final current's resistance.
  EXPECT_NEAR(id->values.at("R"), 37.5, 2.0);
}

class MovingValveWithheld : public ::testing::TestWithParam<const char*> {};

TEST_P(MovingValveWithheld, NamesTheChange) {
  const fs::path dir = kPractice3 / GetParam();
  if (!fs::is_directory(dir)) GTEST_SKIP() << dir << " is missing";
  std::ifstream lf(kPractice3 / "labels.json");
  const nlohmann::json labels = nlohmann::json::parse(lf);
  const auto& label = labels.at(GetParam());
  const Diagnosis d = DiagnoseAgainst((dir / "target").string(), (dir / "reference").string());
  ASSERT_TRUE(d.reference.from_scratch);
  EXPECT_TRUE(Accepted(d.verdict, label.at("accept"))) << GetParam() << ": verdict " << d.verdict << " ("
                                                      << d.verdict_reason << "), truth " << label.at("truth");
}

INSTANTIATE_TEST_SUITE_P(Practice3, MovingValveWithheld, ::testing::Values("m02", "m03", "m04", "m05", "m06"));

// ---- synthetic valves other than practice3's -----------------------------------------------------------------

// A 24 V valve with another coil, stroke, spring, mass and pressure area than practice3's valve-B (37 ohm,
// 12 V) and than the preset, with eddy currents.
model::PlantParams OtherValve() {
  model::PlantParams p = Family();
  p.R_ohm = 62.0;
  p.N_turns = 1332.0;     // L0 = 0.093 H: a 1.5 ms time constant
  p.mu_r = 90.0;
  p.x_max_m = 0.25e-3;
  p.x_t_m = 0.32e-3;
  p.k_N_per_m = 4000.0;
  p.delta_m = 0.49e-3;    // 2 N preload
  p.m_kg = 0.006;
  p.b_N_s_per_m = 0.5;
  p.A1_m2 = 20e-6;
  p.A2_m2 = 24e-6;        // 0.4 N per bar against the pull
  p.effects.eddy_R_p_ohm = 1500.0;
  return p;
}

fs::path TempDir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("vb_moving_" + std::to_string(::getpid()) + "_" + name);
  fs::remove_all(d);
  return d;
}

// The synthetic sets are removed after each test unless VB_KEEP_SYNTHETIC is set (to look at them with benchctl).
void Cleanup(const fs::path& d) {
  if (std::getenv("VB_KEEP_SYNTHETIC") == nullptr) fs::remove_all(d);
}

std::vector<SwitchOnRunPlan> Pressures(double supply_V, std::vector<double> bar, const std::string& split = "") {
  std::vector<SwitchOnRunPlan> out;
  for (double b : bar)
    out.push_back({"on_" + std::to_string(static_cast<int>(b * 10)) + "dbar", supply_V, b * 1e5, -1.0, split});
  return out;
}

TEST(MovingValveSynthetic, GeneratorWritesWhatTheScopeRecords) {
  const fs::path dir = TempDir("gen");
  ScopeChain scope;
  ASSERT_TRUE(WriteSwitchOnSession(dir.string(), OtherValve(), Pressures(24.0, {1, 3}), scope, "other").ok());
  auto ds = LoadDataset(dir.string(), model::PresetNames());
  ASSERT_TRUE(ds.ok()) << ds.status().message();
  ASSERT_EQ(ds->runs.size(), 2u);
  EXPECT_EQ(ds->runs[0].i_A.size(), 1011u);
  // Every value is a multiple of the scope's step.
  for (double i : ds->runs[0].i_A) EXPECT_NEAR(std::round(i * 480.0), i * 480.0, 1e-3);
  EXPECT_TRUE(IsSwitchOnSession(*ds, Family()));
  Cleanup(dir);
}

// OtherValve() at 24 V and 1, 2.5 and 4 bar and at `second_V` (20 V unless said) and 3 bar (fit runs) and at
// `holdouts`, recorded through practice3's scope chain (noise seed `seed`) into `dir` and loaded.
StatusOr<Dataset> OtherValveSession(const fs::path& dir, const std::vector<SwitchOnRunPlan>& holdouts, unsigned seed,
                                    double second_V = 20.0) {
  auto runs = Pressures(24.0, {1, 2.5, 4}, "fit");
  runs.push_back({"on_" + std::to_string(static_cast<int>(second_V)) + "V_3bar", second_V, 3e5, -1.0, "fit"});
  runs.insert(runs.end(), holdouts.begin(), holdouts.end());
  ScopeChain scope;
  scope.seed = seed;
  if (auto st = WriteSwitchOnSession(dir.string(), OtherValve(), runs, scope, "other"); !st.ok()) return st;
  return LoadDataset(dir.string(), model::PresetNames());
}

TEST(MovingValveSynthetic, OtherValveIdentifiedAndPredictedAtAnotherPressureAndSupply) {
  const fs::path dir = TempDir("id");
  // Fit runs at two supplies: at one supply the lift force and the mass trade off (a later lift, a faster
  // flight), and the report says the mass is not determined.
  auto ds = OtherValveSession(
      dir, {{"on_hold_7bar", 24.0, 7e5, -1.0, "holdout"}, {"on_hold_18V", 18.0, 2e5, -1.0, "holdout"}}, 5);
  ASSERT_TRUE(ds.ok()) << ds.status().message();
  auto id = IdentifyMovingValve(*ds, Family());
  ASSERT_TRUE(id.ok()) << id.status().message();
  EXPECT_NEAR(id->values.at("R"), 62.0, 62.0 * 0.02);
  for (const auto& r : id->landmarks) {
    EXPECT_EQ(r.measured.pulls_in, r.predicted.pulls_in) << r.run;
    if (r.split == Split::kHoldout) {
      EXPECT_LT(r.rmse_A, 5e-3) << r.run;
    }
  }
  // The stroke is held at the family's: the mass is found as m x_max^2, the product the current sees.
  for (const auto& d : id->determined)
    if (d.name == "m*x_max^2") {
      EXPECT_NEAR(d.value / (0.006 * 0.25e-3 * 0.25e-3), 1.0, 0.3);
    }
  // Holdouts well inside what the fit runs determine: every draw from the identified values' uncertainty
  // simulates and agrees on pull-in, and the band is narrower than the 5 mA goal.
  for (const auto& r : id->landmarks) {
    if (r.split != Split::kHoldout) continue;
    EXPECT_EQ(r.band_draws, 16) << r.run;
    EXPECT_FALSE(r.pull_in_undetermined) << r.run;
    EXPECT_LT(r.band_spread_A, 5e-3) << r.run;
  }
  const std::string report = MovingIdentificationReport(*id);
  EXPECT_NE(report.find("holdout prediction band"), std::string::npos);
  // The report fits a 120-column terminal (its notes and meanings wrap).
  std::istringstream lines(report);
  for (std::string line; std::getline(lines, line);) EXPECT_LE(line.size(), 120u) << line;
  EXPECT_NE(MovingIdentificationJson(*id).find("\"pull_in_undetermined\": false"), std::string::npos);
  // Each holdout's distance to its pull-in edge along the supply is the true valve's: a valve of the family
  // fitted at the noise carries no bias there (the independent population's is docs/real-data.md, "Eighth round").
  for (std::size_t r = 0; r < ds->runs.size(); ++r) {
    const RunMarks& m = id->landmarks[r];
    if (m.split != Split::kHoldout) continue;
    Dataset one = *ds;
    one.runs = {ds->runs[r]};
    auto truth_pulls = [&](double ratio) {
      one.runs[0].supply_V = ratio * ds->runs[r].supply_V;
      auto p = Predict(one, OtherValve(), PredictOptions{}, {true});
      return p.ok() && FindSwitchOnMarks(p->i_A[0], one.runs[0].gate, one.runs[0].sample_period_s,
                                         4.0 * id->noise_floor_A).pulls_in;
    };
    bool outside = true;
    const double truth = PullInEdgeLogSupply(truth_pulls, &outside);
    ASSERT_FALSE(outside) << m.run << ": the valve's edge lies within half to twice its supply";
    EXPECT_LT(truth, 0.0) << m.run << " pulls in";
    ASSERT_TRUE(std::isfinite(m.edge_log_supply)) << m.run;
    EXPECT_FALSE(m.edge_outside) << m.run;
    EXPECT_NEAR(m.edge_log_supply, truth, 0.02) << m.run;
    // Both holdouts lie 16-18 % of their supply above their edge, inside the bias an identification of a valve
    // outside the family carries there, which the fit runs cannot tell from this one: not trusted, and said why.
    EXPECT_EQ(m.near_pull_in_edge, std::abs(m.edge_log_supply) < kPullInEdgeBiasLogSupply) << m.run;
    EXPECT_TRUE(m.near_pull_in_edge) << m.run;
  }
  EXPECT_NE(id->prediction_undetermined.find("pull-in edge"), std::string::npos) << id->prediction_undetermined;
  // Fit runs at 20 and 24 V, 1.2x apart: judged as at one supply, said so, and the report asks for a run at 0.75x.
  EXPECT_EQ(id->pull_in_edge_bias_log_supply, kPullInEdgeBiasLogSupply);
  EXPECT_EQ(id->pull_in_edge_design, "pulling-in fit runs at 20 to 24 V, less than 1.3x apart: as at one supply");
  bool asks = false;
  for (const auto& n : id->notes)
    asks = asks || n.find("a pulling-in fit run at about 0.75x the highest (18 V)") != std::string::npos;
  EXPECT_TRUE(asks) << "the report asks for a fit run at a second supply";
  EXPECT_NE(report.find("pull-in edge at"), std::string::npos);
  EXPECT_NE(MovingIdentificationJson(*id).find("\"pull_in_edge\""), std::string::npos);
  // The work: counted per stage and in all; this valve (about 280 steps an evaluation) stays far within the
  // default budget (5000 steps an evaluation), which neither ends a stage nor says so.
  std::uint64_t staged = 0;
  for (const auto& s : id->stages) staged += s.ode_steps;
  EXPECT_GT(staged, 0u);
  EXPECT_LE(staged, id->ode_steps);
  for (const auto& n : id->notes) {
    EXPECT_EQ(n.find("the work budget"), std::string::npos) << n;
    EXPECT_EQ(n.find("share of the work"), std::string::npos) << n;
  }
  EXPECT_NE(MovingIdentificationJson(*id).find("\"ode_steps\": " + std::to_string(id->ode_steps)), std::string::npos);
  Cleanup(dir);
}

// The work budget (MovingIdentifyOptions::max_ode_steps) is shared among the stages as their evaluations are
// (budget / max_evaluations steps for each evaluation of a stage's count): each stops at its share, whatever the
// evaluations left, and the identification says which did. This valve's evaluations take about 280 steps
// (measured: its stages' lines), so at 2e6 steps (100 per evaluation) every stage gets about a third of its
// evaluations, the polish still runs, and the whole stays within the budget. Without the shares the first stages
// took it all and the polish never started (the test before 2026-12-01 asked for that).
TEST(MovingValveSynthetic, TheWorkBudgetIsSharedAmongTheStagesAndSaysSo) {
  const fs::path dir = TempDir("work");
  auto ds = OtherValveSession(
      dir, {{"on_hold_7bar", 24.0, 7e5, -1.0, "holdout"}, {"on_hold_18V", 18.0, 2e5, -1.0, "holdout"}}, 5);
  ASSERT_TRUE(ds.ok()) << ds.status().message();
  MovingIdentifyOptions o;
  o.max_ode_steps = 2'000'000;
  auto id = IdentifyMovingValve(*ds, Family(), o);
  ASSERT_TRUE(id.ok()) << id.status().message();
  EXPECT_LE(id->ode_steps, 2'000'000u);
  EXPECT_LT(id->evaluations, 10000) << "the evaluations' own budget (20000) did not end it";
  ASSERT_FALSE(id->stages.empty());
  EXPECT_EQ(id->stages.back().name.rfind("6 polish", 0), 0u) << id->stages.back().name;
  int stage4 = 0;
  for (const auto& s : id->stages) {
    if (s.name.rfind("4 with magnetic saturation", 0) != 0) continue;
    ++stage4;
    // 700 evaluations' share at 100 steps each, past it by the evaluation that crossed it and the final check.
    EXPECT_LE(s.ode_steps, 700u * 100u + 2000u) << s.name;
    EXPECT_LT(s.evaluations, 700) << s.name;
  }
  EXPECT_EQ(stage4, 9) << "three forms from each of three ends";
  bool said = false;
  for (const auto& n : id->notes)
    said = said || (n.rfind("stages ", 0) == 0 && n.find(" 4,") != std::string::npos &&
                    n.find("share of the work (100 solver steps per evaluation") != std::string::npos);
  EXPECT_TRUE(said) << MovingIdentificationReport(*id);
  for (const auto& n : id->notes) EXPECT_EQ(n.find("the work budget ("), std::string::npos) << n;
  EXPECT_TRUE(std::isfinite(id->fit_rmse_A));
  Cleanup(dir);
}

// The same valve, the fourth fit run at 18 V instead of 20 V: pulling-in fit runs 4/3 apart in supply, the design
// whose edge bias was calibrated on its own draws (kPullInEdgeBiasLogSupplyTwoSupplies, 0.149 in log supply). The
// holdouts (7 bar, and 19 V at 2 bar) lie between that bias and the one-supply bias (0.28) above their edges:
// trusted, and predicted within 5 mA. The one-supply bias would have left them undetermined (the test above).
TEST(MovingValveSynthetic, FitRunsAtTwoSuppliesJudgeTheEdgeWithTheirOwnBias) {
  const fs::path dir = TempDir("two");
  auto ds = OtherValveSession(
      dir, {{"on_hold_7bar", 24.0, 7e5, -1.0, "holdout"}, {"on_hold_19V", 19.0, 2e5, -1.0, "holdout"}}, 5, 18.0);
  ASSERT_TRUE(ds.ok()) << ds.status().message();
  auto id = IdentifyMovingValve(*ds, Family());
  ASSERT_TRUE(id.ok()) << id.status().message();
  EXPECT_EQ(id->pull_in_edge_bias_log_supply, kPullInEdgeBiasLogSupplyTwoSupplies);
  EXPECT_EQ(id->pull_in_edge_design, "pulling-in fit runs at 18 and 24 V");
  for (const auto& m : id->landmarks) {
    if (m.split != Split::kHoldout) continue;
    EXPECT_LT(m.rmse_A, 5e-3) << m.run;
    ASSERT_TRUE(std::isfinite(m.edge_log_supply)) << m.run;
    EXPECT_LT(m.edge_log_supply, -kPullInEdgeBiasLogSupplyTwoSupplies) << m.run;
    EXPECT_GT(m.edge_log_supply, -kPullInEdgeBiasLogSupply) << m.run << ": inside the one-supply bias";
    EXPECT_FALSE(m.near_pull_in_edge) << m.run;
  }
  EXPECT_EQ(id->prediction_undetermined, "");
  for (const auto& n : id->notes) EXPECT_EQ(n.find("0.75x"), std::string::npos) << n;
  const std::string json = MovingIdentificationJson(*id);
  EXPECT_NE(json.find("\"pull_in_edge_bias\""), std::string::npos);
  EXPECT_NE(MovingIdentificationReport(*id).find("pull-in edges judged with"), std::string::npos);
  Cleanup(dir);
}

// The same valve, its holdouts inside the fit runs' pressures and supplies and far from their pull-in edge: the
// prediction is a property of what the fit runs determine, and trusted.
TEST(MovingValveSynthetic, APredictionFarFromItsPullInEdgeIsTrusted) {
  const fs::path dir = TempDir("far");
  auto ds = OtherValveSession(
      dir, {{"on_hold_2bar", 24.0, 2e5, -1.0, "holdout"}, {"on_hold_22V", 22.0, 1.5e5, -1.0, "holdout"}}, 6);
  ASSERT_TRUE(ds.ok()) << ds.status().message();
  auto id = IdentifyMovingValve(*ds, Family());
  ASSERT_TRUE(id.ok()) << id.status().message();
  for (const auto& r : id->landmarks) {
    if (r.split != Split::kHoldout) continue;
    EXPECT_LT(r.rmse_A, 5e-3) << r.run;
    EXPECT_FALSE(r.edge_outside) << r.run;
    EXPECT_LT(r.edge_log_supply, -kPullInEdgeBiasLogSupply) << r.run << " pulls in with a margin";
    EXPECT_FALSE(r.near_pull_in_edge) << r.run;
  }
  EXPECT_EQ(id->prediction_undetermined, "") << "a valve of the family fitted at the noise floor, far from its edge";
  Cleanup(dir);
}

// The edge along the supply: where the outcome changes, to 0.3 % of the supply, and said to lie beyond the range
// when it does not change between half and twice the supply.
TEST(PullInEdge, FoundWhereTheOutcomeChangesAndSaidBeyondTheRangeOtherwise) {
  bool outside = true;
  EXPECT_NEAR(PullInEdgeLogSupply([](double r) { return r >= 1.3; }, &outside), std::log(1.3), 0.003);
  EXPECT_FALSE(outside);
  EXPECT_NEAR(PullInEdgeLogSupply([](double r) { return r >= 0.8; }, &outside), std::log(0.8), 0.003);
  EXPECT_FALSE(outside);
  EXPECT_DOUBLE_EQ(PullInEdgeLogSupply([](double) { return true; }, &outside), -std::log(2.0));
  EXPECT_TRUE(outside);
  EXPECT_DOUBLE_EQ(PullInEdgeLogSupply([](double r) { return r > 2.5; }, &outside), std::log(2.0));
  EXPECT_TRUE(outside);
}


// The same valve with a saturating core (tanh form) and a softer spring: the saturation must join the
// identified model (it is decisive) and the holdout runs stay within 5 mA.
TEST(MovingValveSynthetic, SaturatingCoreJoinsTheModelWhenDecisive) {
  const fs::path dir = TempDir("sat");
  model::PlantParams truth = OtherValve();
  truth.effects.saturation_B_T = 0.5;
  truth.effects.saturation_tanh = 1.0;
  truth.k_N_per_m = 2500.0;
  truth.delta_m = 0.6e-3;
  auto runs = Pressures(24.0, {1, 2.5, 4}, "fit");
  runs.push_back({"on_20V_2bar", 20.0, 2e5, -1.0, "fit"});
  runs.push_back({"on_hold_6bar", 24.0, 6e5, -1.0, "holdout"});
  runs.push_back({"on_hold_12V", 12.0, 1e5, -1.0, "holdout"});
  ScopeChain scope;
  scope.seed = 21;
  ASSERT_TRUE(WriteSwitchOnSession(dir.string(), truth, runs, scope, "saturating").ok());
  auto ds = LoadDataset(dir.string(), model::PresetNames());
  ASSERT_TRUE(ds.ok()) << ds.status().message();
  auto id = IdentifyMovingValve(*ds, Family());
  ASSERT_TRUE(id.ok()) << id.status().message();
  EXPECT_NE(std::find(id->effects.begin(), id->effects.end(), "magnetic_saturation"), id->effects.end())
      << MovingIdentificationReport(*id);
  for (const auto& r : id->landmarks) {
    EXPECT_EQ(r.measured.pulls_in, r.predicted.pulls_in) << r.run;
    if (r.split == Split::kHoldout) {
      EXPECT_LT(r.rmse_A, 5e-3) << r.run << "\n" << MovingIdentificationReport(*id);
    }
  }
  Cleanup(dir);
}

struct Change {
  const char* name;
  void (*apply)(model::PlantParams*, std::vector<SwitchOnRunPlan>*);
  const char* accept;  // a word the verdict must contain
};

const Change kChanges[] = {
    {"none", [](model::PlantParams*, std::vector<SwitchOnRunPlan>*) {}, "none"},
    {"resistance", [](model::PlantParams* p, std::vector<SwitchOnRunPlan>*) { p->R_ohm *= 1.05; }, "R"},
    {"stuck",
     [](model::PlantParams* p, std::vector<SwitchOnRunPlan>*) {
       p->effects.friction_F_c_N = 100.0;
       p->effects.friction_F_s_N = 100.0;
     },
     "stuck"},
    {"spring", [](model::PlantParams* p, std::vector<SwitchOnRunPlan>*) { p->delta_m *= 0.85; }, "delta"},
    {"pressure",
     [](model::PlantParams*, std::vector<SwitchOnRunPlan>* runs) {
       for (auto& r : *runs) {
         r.declared_pressure_Pa = 1e5;
         r.supply_pressure_Pa = 5e5;
       }
     },
     "pressure"},
    {"gain", [](model::PlantParams* p, std::vector<SwitchOnRunPlan>*) { p->effects.sensor_gain = 0.96; }, "sensor_gain"},
    {"smaller_R", [](model::PlantParams* p, std::vector<SwitchOnRunPlan>*) { p->R_ohm *= 0.975; }, "R"},
    // The changes of a valve in service (issue 35, point 4). Wear: dry friction at a sixth of the 2 N preload.
    {"wear",
     [](model::PlantParams* p, std::vector<SwitchOnRunPlan>*) {
       p->effects.friction_F_c_N = 0.3;
       p->effects.friction_F_s_N = 0.4;
     },
     "friction|param:b"},
    // Spring fatigue: the stiffness 30 % lower, and with it the preload force k (x_min + delta).
    {"fatigue", [](model::PlantParams* p, std::vector<SwitchOnRunPlan>*) { p->k_N_per_m *= 0.7; }, "param:k|param:delta"},
    // A corroded connector: 4 % of the winding in series with the supply. A switch-on cannot tell it from R.
    {"connector", [](model::PlantParams* p, std::vector<SwitchOnRunPlan>*) { p->effects.supply_R_ohm = 2.5; },
     "supply_resistance"},
    {"low_supply", [](model::PlantParams* p, std::vector<SwitchOnRunPlan>*) { p->effects.supply_gain = 0.93; },
     "supply_voltage"},
    {"slow_driver", [](model::PlantParams* p, std::vector<SwitchOnRunPlan>*) { p->effects.driver_delay_s = 60e-6; },
     "driver_delay"},
};

// Whether the verdict contains one of the '|'-separated words.
bool Accepts(const std::string& verdict, const std::string& accept) {
  std::size_t a = 0;
  while (a <= accept.size()) {
    const std::size_t b = std::min(accept.find('|', a), accept.size());
    if (verdict.find(accept.substr(a, b - a)) != std::string::npos) return true;
    a = b + 1;
  }
  return false;
}

class MovingValveSyntheticChange : public ::testing::TestWithParam<int> {};

TEST_P(MovingValveSyntheticChange, NamedAgainstAReferenceIdentifiedFromScratch) {
  const Change& c = kChanges[GetParam()];
  const fs::path ref = TempDir(std::string("ref_") + c.name), tgt = TempDir(std::string("tgt_") + c.name);
  ScopeChain scope;
  scope.seed = 11;
  ASSERT_TRUE(WriteSwitchOnSession(ref.string(), OtherValve(), Pressures(24.0, {1, 2.5, 4, 6}), scope, "other").ok());
  model::PlantParams later = OtherValve();
  auto runs = std::string(c.name) == "pressure" ? Pressures(24.0, {1, 1, 1}) : Pressures(24.0, {1, 2.5, 4, 6});
  for (std::size_t k = 0; k < runs.size(); ++k) runs[k].id.append("_").append(std::to_string(k));
  c.apply(&later, &runs);
  scope.seed = 12;
  ASSERT_TRUE(WriteSwitchOnSession(tgt.string(), later, runs, scope, "other", "taghizadeh2009", 100.0).ok());
  const Diagnosis d = DiagnoseAgainst(tgt.string(), ref.string());
  EXPECT_TRUE(Accepts(d.verdict, c.accept)) << c.name << ": verdict " << d.verdict << " (" << d.verdict_reason << ")";
  Cleanup(ref);
  Cleanup(tgt);
}

INSTANTIATE_TEST_SUITE_P(OtherValve, MovingValveSyntheticChange, ::testing::Range(0, static_cast<int>(std::size(kChanges))),
                         [](const ::testing::TestParamInfo<int>& i) { return std::string(kChanges[i.param].name); });

// A change against a reference that is not identified is not named (gap/diagnose.cc UntrustedName): the reference's
// parameters do not move the current as the valve's do, and perf_changes measured every confident wrong name on
// such references. The reference gets too few evaluations to be identified; the change (30 % of the winding's
// resistance in series with the supply) is far above its fit error.
TEST(MovingValve, AChangeAgainstAReferenceThatIsNotIdentifiedIsNotNamed) {
  const fs::path ref = TempDir("untrusted_ref"), tgt = TempDir("untrusted_tgt");
  ScopeChain scope;
  scope.seed = 21;
  ASSERT_TRUE(WriteSwitchOnSession(ref.string(), OtherValve(), Pressures(24.0, {1, 2.5, 4, 6}), scope, "other").ok());
  auto runs = Pressures(24.0, {1, 2.5, 4, 6});
  for (std::size_t k = 0; k < runs.size(); ++k) runs[k].id.append("_").append(std::to_string(k));
  model::PlantParams later = OtherValve();
  later.effects.supply_R_ohm = 0.3 * later.R_ohm;  // a corroded connector: the current falls by a quarter
  scope.seed = 22;
  ASSERT_TRUE(WriteSwitchOnSession(tgt.string(), later, runs, scope, "other", "taghizadeh2009", 100.0).ok());
  // 500 evaluations (a count: the same on any machine) leave this reference at 15 mA RMS on 0.7 mA of noise; the
  // best row, against it, is a supply voltage (a wrong name for a series resistance, which the rule withholds).
  const Diagnosis d = DiagnoseAgainst(tgt.string(), ref.string(), 500);
  ASSERT_FALSE(d.reference.identified()) << "reference fit " << d.reference.fit_rmse_A << " A";
  EXPECT_EQ(d.verdict_kind, VerdictKind::kUndetermined) << d.verdict << ": " << d.verdict_reason;
  EXPECT_LT(d.chosen, 0);
  EXPECT_FALSE(d.untrusted_name.empty()) << d.verdict_reason;
  EXPECT_NE(d.verdict_reason.find("cannot tell which change"), std::string::npos) << d.verdict_reason;
  EXPECT_NE(d.verdict_reason.find(d.untrusted_name), std::string::npos) << d.verdict_reason;
  EXPECT_NE(DiagnosisJson(d).find("\"untrusted_name\""), std::string::npos);
  Cleanup(ref);
  Cleanup(tgt);
}

TEST(MovingValve, OneRunSaysNothingCanBeHeldOut) {
  const fs::path ref = TempDir("one_ref"), tgt = TempDir("one_tgt");
  ScopeChain scope;
  ASSERT_TRUE(WriteSwitchOnSession(ref.string(), OtherValve(), Pressures(24.0, {1, 3, 6}), scope, "other").ok());
  model::PlantParams later = OtherValve();
  later.R_ohm *= 1.1;
  ASSERT_TRUE(WriteSwitchOnSession(tgt.string(), later, Pressures(24.0, {1}), scope, "other", "taghizadeh2009", 50).ok());
  const Diagnosis d = DiagnoseAgainst(tgt.string(), ref.string());
  EXPECT_EQ(d.verdict, "unknown");
  EXPECT_NE(d.verdict_reason.find("nothing can be held out"), std::string::npos) << d.verdict_reason;
  EXPECT_TRUE(d.ranking.empty());
  Cleanup(ref);
  Cleanup(tgt);
}

// A diagnosis's reference identified from scratch works within the step budget it is given
// (IdentifyOptions::scratch_max_ode_steps), shared among its stages, and says so in the reference's notes: at 2e6
// steps (100 an evaluation, where this valve's take about 280) every stage stops at its share. The one-run target
// ends the diagnosis right after the reference.
TEST(MovingValve, TheReferenceIsIdentifiedWithinTheStepBudgetItIsGiven) {
  const fs::path ref = TempDir("budget_ref"), tgt = TempDir("budget_tgt");
  ScopeChain scope;
  ASSERT_TRUE(WriteSwitchOnSession(ref.string(), OtherValve(), Pressures(24.0, {1, 3, 6}), scope, "other").ok());
  ASSERT_TRUE(
      WriteSwitchOnSession(tgt.string(), OtherValve(), Pressures(24.0, {1}), scope, "other", "taghizadeh2009", 50).ok());
  auto said = [](const Diagnosis& d) {
    for (const auto& n : d.reference.notes)
      if (n.find("share of the work (100 solver steps per evaluation") != std::string::npos) return true;
    return false;
  };
  const Diagnosis budgeted = DiagnoseAgainst(tgt.string(), ref.string(), 0, 2'000'000);
  EXPECT_TRUE(budgeted.reference.from_scratch);
  EXPECT_TRUE(said(budgeted));
  EXPECT_TRUE(std::isfinite(budgeted.reference.fit_rmse_A));
  const Diagnosis by_default = DiagnoseAgainst(tgt.string(), ref.string());
  EXPECT_FALSE(said(by_default)) << "the default budget (5000 steps an evaluation) does not bind on this valve";
  Cleanup(ref);
  Cleanup(tgt);
}

TEST(MovingValve, APwmSessionIsNotASwitchOnSession) {
  const fs::path dir = kPractice3.parent_path() / "practice" / "p05";
  if (!fs::is_directory(dir)) GTEST_SKIP() << dir << " is missing";
  auto ds = LoadDataset(dir.string(), model::PresetNames());
  ASSERT_TRUE(ds.ok()) << ds.status().message();
  EXPECT_FALSE(IsSwitchOnSession(*ds, Family()));
}

TEST(MovingValve, RefusesWhatIsNotASwitchOnSession) {
  Dataset ds;
  ds.format = "valve-runs/2";
  RunData r;
  r.kind = RunKind::kPeriodic;
  ds.runs.push_back(r);
  auto id = IdentifyMovingValve(ds, Family());
  ASSERT_FALSE(id.ok());
  EXPECT_NE(id.status().message().find("--params"), std::string::npos);
}

// The declared conditions decide between confusable changes: a warmer winding predicts R, not the sense gain.
TEST(PreferDeclared, WarmerWindingNamesTheResistanceOverAConfusableSenseGain) {
  Diagnosis d;
  d.has_reference = true;
  d.reference.temperature_C = 26.0;
  for (const char* n : {"sensor_gain", "resistance_temperature", "param:R"}) {
    CandidateResult r;
    r.name = n;
    d.ranking.push_back(r);
    d.candidates.push_back(Candidate{n, {}, {}});
  }
  d.chosen = 0;
  d.verdict = "sensor_gain";
  d.confusable = {"resistance_temperature", "param:R"};
  Dataset target;
  RunData hot;
  hot.coil_C = 41.0;
  target.runs.push_back(hot);
  Diagnosis same = d;
  EXPECT_EQ(ChooseAmongConfusable(&d, target), "");  // one cause, not "either of"
  EXPECT_EQ(d.chosen, 0);
  EXPECT_EQ(d.ranking.front().name, "resistance_temperature");
  EXPECT_EQ(d.candidates.front().name, "resistance_temperature");
  EXPECT_NE(std::find(d.confusable.begin(), d.confusable.end(), "sensor_gain"), d.confusable.end());
  // At the reference's temperature nothing predicts a change of R: the ranking stands.
  target.runs.front().coil_C = 26.5;
  EXPECT_EQ(ChooseAmongConfusable(&same, target), "");
  EXPECT_EQ(same.ranking.front().name, "sensor_gain");
}

// ---- scope captures in (benchctl convert --channel) -------------------------------------------------------------

// A capture as a bench scope exports it: header lines, a column-name line, the time from -pre-trigger, a gate
// drive channel and a shunt voltage.
std::string ScopeCapture(double shunt_ohm, const std::string& bad_cell = "") {
  std::ostringstream os;
  os << "Model,DS1104Z\nX,CH1,CH2\nSecond,Volt,Volt\n";
  for (int k = 0; k < 200; ++k) {
    const double t = -1e-4 + k * 1e-5;
    const bool on = t >= 0.0;
    const double i = on ? 0.3 * (1.0 - std::exp(-t / 1e-3)) : 0.0;
    os << t << "," << (on ? 5.0 : 0.0) << ",";
    if (k == 50 && !bad_cell.empty())
      os << bad_cell;
    else
      os << i * shunt_ohm;
    os << "\n";
  }
  return os.str();
}

TEST(ScopeCsv, CaptureBecomesARunOfADataset) {
  const fs::path dir = TempDir("scope");
  fs::create_directories(dir);
  const fs::path csv = dir / "cap1.csv";
  std::ofstream(csv) << ScopeCapture(0.5);
  ScopeCsvOptions o;
  o.current_channel = "CH2";
  o.shunt_ohm = 0.5;
  o.gate_channel = "CH1";
  o.supply_V = 12.0;
  o.supply_pressure_Pa = 2e5;
  o.split = "fit";
  o.noise_A = 1e-3;
  o.averaged = 8;
  auto run = ConvertScopeCsv(csv.string(), (dir / "ds").string(), o);
  ASSERT_TRUE(run.ok()) << run.status().message();
  EXPECT_EQ(run->samples, 200u);
  EXPECT_NEAR(run->sample_period_s, 1e-5, 1e-12);
  EXPECT_NEAR(run->gate_on_s, 1e-4, 1e-9);
  // A second capture, by trigger time, is appended after the first.
  o.gate_channel.clear();
  o.trigger_s = 0.0;
  o.run_id = "cap2";
  ASSERT_TRUE(ConvertScopeCsv(csv.string(), (dir / "ds").string(), o).ok());
  auto ds = LoadDataset((dir / "ds").string(), model::PresetNames());
  ASSERT_TRUE(ds.ok()) << ds.status().message();
  ASSERT_EQ(ds->runs.size(), 2u);
  EXPECT_EQ(ds->runs[0].gate, ds->runs[1].gate);
  EXPECT_NEAR(ds->runs[0].i_A.back(), 0.3 * (1.0 - std::exp(-(199 * 1e-5 - 1e-4) / 1e-3)), 1e-6);
  EXPECT_GT(ds->runs[1].t_start_s, ds->runs[0].t_start_s);
  EXPECT_TRUE(IsSwitchOnSession(*ds, Family()));
  Cleanup(dir);
}

TEST(ScopeCsv, ErrorsNameLineAndColumn) {
  const fs::path dir = TempDir("scope_bad");
  fs::create_directories(dir);
  const fs::path csv = dir / "cap.csv";
  std::ofstream(csv) << ScopeCapture(1.0, "0.1x");
  ScopeCsvOptions o;
  o.current_channel = "CH2";
  o.shunt_ohm = 1.0;
  o.trigger_s = 0.0;
  o.supply_V = 12.0;
  auto run = ConvertScopeCsv(csv.string(), (dir / "ds").string(), o);
  ASSERT_FALSE(run.ok());
  // 3 header lines, then data: the 51st data row is line 54.
  EXPECT_NE(run.status().message().find("cap.csv:54: column CH2: '0.1x' is not a number"), std::string::npos)
      << run.status().message();
  o.current_channel = "CH9";
  run = ConvertScopeCsv(csv.string(), (dir / "ds").string(), o);
  ASSERT_FALSE(run.ok());
  EXPECT_NE(run.status().message().find("no column 'CH9'"), std::string::npos) << run.status().message();
  o.current_channel = "CH2";
  o.probe_A_per_V = 10.0;  // and a shunt: one of the two
  run = ConvertScopeCsv(csv.string(), (dir / "ds").string(), o);
  ASSERT_FALSE(run.ok());
  EXPECT_NE(run.status().message().find("exactly one of --shunt-ohm"), std::string::npos);
  // One column in two roles (found by fuzz_scope_csv: the gate's samples were never read, and an empty channel
  // was searched for its range).
  o.probe_A_per_V = 0.0;
  o.trigger_s = NAN;
  o.gate_channel = "CH2";
  run = ConvertScopeCsv(csv.string(), (dir / "ds").string(), o);
  ASSERT_FALSE(run.ok());
  EXPECT_NE(run.status().message().find("--gate-channel: 'CH2' is the current's channel"), std::string::npos)
      << run.status().message();
  o.gate_channel.clear();
  o.trigger_s = 0.0;
  o.current_channel = "1";  // the time column
  run = ConvertScopeCsv(csv.string(), (dir / "ds").string(), o);
  ASSERT_FALSE(run.ok());
  EXPECT_NE(run.status().message().find("--channel: '1' is the time column"), std::string::npos) << run.status().message();
  Cleanup(dir);
}

}  // namespace
}  // namespace vb::gap
