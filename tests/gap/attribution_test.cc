// Attribution on synthetic bench sessions: the emulator with a known effect on stands in for the bench (the
// catalog's effects are the emulator's), plus 2 mA of Gaussian sensor noise. Short runs keep this fast.
#include <gtest/gtest.h>

#include <random>

#include "gap/attribution.h"
#include "gap/diagnose.h"
#include "synthetic_session.h"

namespace vb::gap {
namespace {

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
  o.try_combinations = pairs;
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
