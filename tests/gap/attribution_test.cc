// Attribution on synthetic bench sessions: the emulator with a known effect on stands in for the bench (the
// catalog's effects are the emulator's), plus 2 mA of Gaussian sensor noise. Short runs keep this fast.
#include <gtest/gtest.h>

#include <random>

#include "gap/attribution.h"
#include "gap/diagnose.h"

namespace vb::gap {
namespace {

struct RunPlan {
  const char* id;
  double supply_V;
  double pwm_Hz;   // 0: one step on
  double duty;
  const char* split;
};

// Gate pattern: PWM at pwm_Hz and duty for 40 ms (or a 20 ms step), then 10 ms off.
std::vector<std::int8_t> Gate(const RunPlan& p, double dt) {
  const std::size_t n = static_cast<std::size_t>(0.05 / dt);
  std::vector<std::int8_t> g(n, 0);
  for (std::size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * dt;
    if (p.pwm_Hz == 0.0) {
      g[k] = t < 0.02;
    } else if (t < 0.04) {
      const double phase = std::fmod(t * p.pwm_Hz, 1.0);
      g[k] = phase < p.duty;
    }
  }
  return g;
}

const std::vector<RunPlan>& Plans() {
  static const std::vector<RunPlan> plans = {
      {"step24", 24.0, 0, 1, "fit"},        {"pwm200_d60", 24.0, 200, 0.6, "fit"},
      {"pwm500_d40", 24.0, 500, 0.4, "fit"}, {"step18", 18.0, 0, 1, "holdout"},
      {"pwm300_d50_18", 18.0, 300, 0.5, "holdout"},
  };
  return plans;
}

Dataset Session(const model::PlantParams& truth, unsigned seed = 7, double noise_A = 2e-3) {
  Dataset ds;
  ds.format = "valve-runs/1";
  ds.model = "taghizadeh2009";
  const double dt = 2e-5;
  std::vector<SessionRun> runs;
  double t0 = 0.5;
  for (const auto& p : Plans()) {
    RunData r;
    r.id = p.id;
    r.supply_V = p.supply_V;
    r.supply_pressure_Pa = 3e5;
    r.t_start_s = t0;
    r.split = p.split;
    r.sample_period_s = dt;
    r.gate = Gate(p, dt);
    for (std::size_t k = 0; k < r.gate.size(); ++k) r.t_s.push_back(static_cast<double>(k) * dt);
    t0 += 0.2;
    ds.runs.push_back(std::move(r));
  }
  for (const auto& r : ds.runs) runs.push_back({r.supply_V, r.supply_pressure_Pa, r.sample_period_s, r.t_start_s, &r.gate});
  auto reps = ReplaySession(truth, model::DriverParams{}, runs);
  EXPECT_TRUE(reps.ok()) << reps.status().message();
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, noise_A);
  for (std::size_t r = 0; r < ds.runs.size(); ++r)
    for (double i : (*reps)[r].i_A) ds.runs[r].i_A.push_back(i + noise(rng));
  return ds;
}

model::PlantParams With(const char* effect, std::vector<std::pair<std::string, double>> params) {
  model::PlantParams p = *model::Preset("taghizadeh2009");
  EXPECT_TRUE(model::AddEffect(&p.effects, effect, params).ok());
  return p;
}

std::vector<Candidate> Pick(const std::vector<std::string>& names) {
  std::vector<Candidate> out;
  for (const auto& c : DefaultCandidates(*model::Preset("taghizadeh2009")))
    if (std::find(names.begin(), names.end(), c.name) != names.end()) out.push_back(c);
  EXPECT_EQ(out.size(), names.size());
  return out;
}

DiagnoseOptions Options(const std::vector<std::string>& names, bool pairs = false) {
  DiagnoseOptions o;
  o.candidates = Pick(names);
  o.try_pairs = pairs;
  o.overlay_points = 100;
  return o;
}

// The labelled effect wins, its fitted parameter lands on the truth, and the holdout gap closes.
TEST(Attribution, NamesTheEffectAndRecoversItsParameter) {
  const auto ds = Session(With("supply_resistance", {{"R_s", 0.8}}));
  auto d = Diagnose(ds, *model::Preset("taghizadeh2009"),
                    Options({"param:R", "supply_resistance", "eddy_currents", "sensor_lag"}));
  ASSERT_TRUE(d.ok()) << d.status().message();
  ASSERT_TRUE(d->significant);
  EXPECT_EQ(d->verdict, "supply_resistance");
  const auto& best = d->ranking.front();
  EXPECT_NEAR(best.params.at("supply_resistance.R_s"), 0.8, 0.05);
  EXPECT_NEAR(best.params.at("R"), 13.0, 0.1);
  ASSERT_TRUE(best.uncertainty.count("supply_resistance.R_s"));
  EXPECT_GT(best.uncertainty.at("supply_resistance.R_s"), 0.0);
  EXPECT_GT(best.closed, 0.9);
  EXPECT_LT(best.holdout_rmse_after_A, 2.5e-3);
  EXPECT_GT(best.holdout_rmse_before_A, 5e-3);
  EXPECT_GE(d->parametric, 0);
  EXPECT_EQ(d->ranking[static_cast<std::size_t>(d->parametric)].name, "param:R");
  // How far, per phase, and the overlays for plots.
  EXPECT_EQ(d->overlays.size(), ds.runs.size());
  EXPECT_EQ(d->overlays.front().fitted_A.size(), d->overlays.front().measured_A.size());
  const std::string json = DiagnosisJson(*d);
  for (const char* key : {"\"ranking\"", "\"effect\"", "\"params\"", "\"holdout_rmse_before_A\"",
                          "\"holdout_rmse_after_A\"", "\"closed\"", "\"how_far\"", "\"overlays\"", "\"landmarks\""})
    EXPECT_NE(json.find(key), std::string::npos) << key;
}

// Holdout runs never reach the fit: wrecking their measured currents changes nothing fitted, only the score.
TEST(Attribution, HoldoutRunsNeverReachTheFit) {
  const auto clean = Session(With("supply_resistance", {{"R_s", 0.8}}));
  Dataset wrecked = clean;
  for (auto& r : wrecked.runs)
    if (r.split == "holdout")
      for (double& i : r.i_A) i += 0.3;
  std::vector<bool> mask;
  for (const auto& r : clean.runs) mask.push_back(r.split == "fit");
  const auto cands = Pick({"supply_resistance"});
  auto a = Attribute(clean, mask, *model::Preset("taghizadeh2009"), cands, 2e-3);
  auto b = Attribute(wrecked, mask, *model::Preset("taghizadeh2009"), cands, 2e-3);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->front().params, b->front().params);
  EXPECT_EQ(a->front().fit_rmse_A, b->front().fit_rmse_A);
  EXPECT_GT(b->front().holdout_rmse_after_A, 0.25);
}

// Nothing in the candidate list explains eddy currents: "unknown", not the least bad candidate.
TEST(Attribution, UnknownWhenNoCandidateClosesTheGap) {
  const auto ds = Session(With("eddy_currents", {{"R_p", 150.0}}));
  auto d = Diagnose(ds, *model::Preset("taghizadeh2009"), Options({"param:R", "param:k"}));
  ASSERT_TRUE(d.ok());
  ASSERT_TRUE(d->significant);
  EXPECT_EQ(d->verdict, "unknown");
  EXPECT_LT(d->ranking.front().closed, kExplained);
  EXPECT_NE(DiagnosisReport(*d).find("verdict: unknown"), std::string::npos);
}

// Two effects at once: neither alone closes the gap, the pair does.
TEST(Attribution, TriesPairsWhenNoSingleEffectCloses) {
  model::PlantParams truth = With("supply_resistance", {{"R_s", 1.5}});
  ASSERT_TRUE(model::AddEffect(&truth.effects, "sensor_lag", {{"tau_s", 3e-4}}).ok());
  const auto ds = Session(truth);
  auto d = Diagnose(ds, *model::Preset("taghizadeh2009"), Options({"supply_resistance", "sensor_lag"}, true));
  ASSERT_TRUE(d.ok());
  EXPECT_TRUE(d->verdict == "supply_resistance+sensor_lag" || d->verdict == "sensor_lag+supply_resistance")
      << DiagnosisReport(*d);
}

// Effect-free data: no attribution at all, the verdict is none.
TEST(Attribution, NoneSkipsTheFit) {
  const auto ds = Session(*model::Preset("taghizadeh2009"));
  auto d = Diagnose(ds, *model::Preset("taghizadeh2009"), Options({"param:R"}));
  ASSERT_TRUE(d.ok());
  EXPECT_FALSE(d->significant);
  EXPECT_EQ(d->verdict, "none");
  EXPECT_TRUE(d->ranking.empty());
}

// A practice dataset end to end with the full catalog (the slowest test here, a few seconds).
TEST(Attribution, PracticeSensorLagWithTheFullCatalog) {
  auto ds = LoadDataset(std::string(VB_SHARED_DIR) + "/gapbench/practice/p11");
  if (!ds.ok()) GTEST_SKIP() << ds.status().message();
  auto d = Diagnose(*ds, *model::Preset("taghizadeh2009"));
  ASSERT_TRUE(d.ok());
  EXPECT_EQ(d->verdict, "sensor_lag");
  EXPECT_GT(d->ranking.front().closed, 0.9);
}


// Bounded fits: a candidate that runs out of its wall-time budget is reported as failed with the reason, and
// the diagnosis goes on with the others.
TEST(Attribution, ACandidateOutOfTimeFailsWithItsReasonAndTheOthersGoOn) {
  const model::PlantParams nominal = *model::Preset("taghizadeh2009");
  const Dataset ds = Session(With("supply_resistance", {{"R_s", 0.8}}), 3);
  std::vector<Candidate> cands = Pick({"supply_resistance", "param:R", "eddy_currents"});
  AttributionOptions opt;
  opt.candidate_budget_s = 1e-6;  // nothing can be fitted in a microsecond
  std::vector<bool> mask;
  for (const auto& r : ds.runs) mask.push_back(r.split != "holdout");
  auto rows = Attribute(ds, mask, nominal, cands, 0.002, opt);
  ASSERT_TRUE(rows.ok()) << rows.status().message();
  ASSERT_EQ(rows->size(), cands.size());
  for (const auto& row : *rows) {
    EXPECT_FALSE(row.status.ok()) << row.name;
    EXPECT_NE(row.status.message().find("wall-time budget"), std::string::npos) << row.status.message();
  }
  // A whole diagnosis with its deadline already gone still answers, saying why nothing was fitted.
  DiagnoseOptions dopt;
  dopt.budget_s = 0.0;
  auto d = Diagnose(ds, nominal, dopt);
  ASSERT_TRUE(d.ok()) << d.status().message();
  EXPECT_EQ(d->verdict, "unknown");
  EXPECT_NE(d->ranking.front().status.message().find("time budget"), std::string::npos);
}

}  // namespace
}  // namespace vb::gap
