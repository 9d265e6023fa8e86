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

// The saturation's knee in the form the data have (issue 36, point 3): a core that saturates like tanh is fitted
// as tanh, and then leaves only the noise on the holdout runs; one of Frohlich's form keeps Frohlich's. Fitted
// with Frohlich's form alone, the tanh core left a structured residual that a second cause was taken for.
TEST(Attribution, TheSaturationIsFittedInTheFormOfItsKnee) {
  for (double form : {1.0, 0.0}) {
    const auto ds = Session(With("magnetic_saturation", {{"B_sat", 2.0}, {"tanh", form}}));
    auto d = Diagnose(ds, *model::Preset("taghizadeh2009"), Options({"param:R", "magnetic_saturation"}));
    ASSERT_TRUE(d.ok()) << d.status().message();
    EXPECT_EQ(d->verdict, "magnetic_saturation") << form;
    const auto& best = d->ranking.front();
    ASSERT_EQ(best.name, "magnetic_saturation");
    EXPECT_EQ(best.params.at("magnetic_saturation.tanh"), form);
    EXPECT_NEAR(best.params.at("magnetic_saturation.B_sat"), 2.0, 0.15) << form;
    EXPECT_LT(best.holdout_rmse_after_A, 2.5e-3) << form;  // the noise is 2 mA
    EXPECT_EQ(best.uncertainty.count("magnetic_saturation.tanh"), 0u);  // a choice, not a measured value
    if (!best.correlation.empty()) {
      EXPECT_EQ(best.correlation.size(), 3u);  // laid out as the candidate's params
    }
  }
}

// Holdout runs never reach the fit: wrecking their measured currents changes nothing fitted, only the score.
TEST(Attribution, HoldoutRunsNeverReachTheFit) {
  const auto clean = Session(With("supply_resistance", {{"R_s", 0.8}}));
  Dataset wrecked = clean;
  for (auto& r : wrecked.runs)
    if (r.split == Split::kHoldout)
      for (double& i : r.i_A) i += 0.3;
  std::vector<bool> mask;
  for (const auto& r : clean.runs) mask.push_back(r.split == Split::kFit);
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
  // Where the gap lies (its largest phase), which is what the user can act on.
  EXPECT_NE(d->verdict_reason.find("the gap lies in " + std::string(PhaseName(d->where.front().phase))), std::string::npos)
      << d->verdict_reason;
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
  for (const auto& r : ds.runs) mask.push_back(r.split != Split::kHoldout);
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

namespace vb::gap {
namespace {

}  // namespace
}  // namespace vb::gap

namespace vb::gap {
namespace {

// Three effects at once: no single one and no pair explains the session; the beam finds all three.
TEST(Attribution, FindsThreeSimultaneousEffects) {
  model::PlantParams truth = With("supply_resistance", {{"R_s", 0.8}});
  ASSERT_TRUE(model::AddEffect(&truth.effects, "eddy_currents", {{"R_p", 300.0}}).ok());
  ASSERT_TRUE(model::AddEffect(&truth.effects, "sensor_lag", {{"tau_s", 2e-4}}).ok());
  const auto ds = Session(truth);
  DiagnoseOptions o = Options({"param:R", "supply_resistance", "eddy_currents", "sensor_lag", "end_stop_bounce",
                               "coulomb_friction"}, true);
  o.detection_limits = false;
  auto d = Diagnose(ds, *model::Preset("taghizadeh2009"), o);
  ASSERT_TRUE(d.ok()) << d.status().message();
  std::vector<std::string> got;
  for (std::size_t a = 0, b; a <= d->verdict.size(); a = b + 1) {
    b = d->verdict.find('+', a);
    if (b == std::string::npos) b = d->verdict.size();
    got.push_back(d->verdict.substr(a, b - a));
  }
  std::sort(got.begin(), got.end());
  EXPECT_EQ(got, (std::vector<std::string>{"eddy_currents", "sensor_lag", "supply_resistance"})) << DiagnosisReport(*d);
  EXPECT_GT(d->ranking.front().closed, 0.9);
}

}  // namespace
}  // namespace vb::gap

namespace vb::gap {
namespace {

std::vector<std::string> VerdictMembers(const std::string& verdict) {
  std::vector<std::string> got;
  for (std::size_t a = 0, b; a <= verdict.size(); a = b + 1) {
    b = verdict.find('+', a);
    if (b == std::string::npos) b = verdict.size();
    got.push_back(verdict.substr(a, b - a));
  }
  std::sort(got.begin(), got.end());
  return got;
}

// Masking (docs/gap.md, "Several causes"): a strong saturating core hides dry friction from the friction's own
// single fit. With a pool of one, pairs among single fits are impossible: only the best single's partners, every
// structural effect fitted beside it, can find the friction.
TEST(Attribution, AMaskedSecondCauseIsFoundBesideTheStrongerOne) {
  model::PlantParams truth = With("magnetic_saturation", {{"B_sat", 1.2}});
  ASSERT_TRUE(model::AddEffect(&truth.effects, "coulomb_friction", {{"F_c", 1.5}, {"F_s", 2.2}}).ok());
  const auto ds = Session(truth);
  DiagnoseOptions o = Options({"param:R", "magnetic_saturation", "coulomb_friction", "eddy_currents", "supply_resistance",
                               "end_stop_bounce"}, true);
  o.combination_pool = 1;
  o.max_effects = 2;
  o.detection_limits = false;
  auto d = Diagnose(ds, *model::Preset("taghizadeh2009"), o);
  ASSERT_TRUE(d.ok()) << d.status().message();
  EXPECT_EQ(VerdictMembers(d->verdict), (std::vector<std::string>{"coulomb_friction", "magnetic_saturation"}))
      << DiagnosisReport(*d);
  // Each cause's own share beside what both close together.
  ASSERT_EQ(d->members.size(), 2u);
  for (const auto& m : d->members) {
    EXPECT_LT(m.closed, d->ranking.front().closed) << m.name;
    EXPECT_GT(m.gap_A, 0.0) << m.name;
  }
  EXPECT_NE(DiagnosisReport(*d).find("each cause on its own closes"), std::string::npos);
  EXPECT_NE(DiagnosisJson(*d).find("\"members\""), std::string::npos);
}

// Below the gate (docs/gap.md, "Below the gate"): a weak coil heating beside an end-stop bounce leaves, once the
// bounce is fitted, less than a significant gap on the holdout runs, where issue 26's rules take nothing; the
// evidence rule there names it, against the bounce with its best drift as well. And a nuisance drift of the
// spring beside the bounce alone is not taken for a second cause there.
TEST(Attribution, AWeakSecondCauseBelowTheGateIsFoundAndADriftIsNot) {
  const std::vector<std::string> names = {"param:R", "param:k", "param:delta", "end_stop_bounce", "coil_heating",
                                          "eddy_currents", "sensor_gain"};
  model::PlantParams truth = With("end_stop_bounce", {{"e", 0.49}});
  ASSERT_TRUE(model::AddEffect(&truth.effects, "coil_heating", {{"R_th", 1.5}, {"C_th", 0.35}}).ok());
  const auto ds = Session(truth);
  DiagnoseOptions o = Options(names, true);
  o.detection_limits = false;
  o.max_effects = 2;
  auto d = Diagnose(ds, *model::Preset("taghizadeh2009"), o);
  ASSERT_TRUE(d.ok()) << d.status().message();
  EXPECT_EQ(VerdictMembers(d->verdict), (std::vector<std::string>{"coil_heating", "end_stop_bounce"}))
      << DiagnosisReport(*d);
  // The step that named it was judged below the gate, against the bounce or the bounce with a drift.
  bool below = false;
  for (const auto& a : d->additions)
    if (a.taken && a.before_A <= kSignificance * d->noise_floor_A) below = true;
  EXPECT_TRUE(below) << DiagnosisReport(*d);
  // With issue 26's gate as it was, the heating is not searched for.
  o.evidence_below_gate = false;
  auto gated = Diagnose(ds, *model::Preset("taghizadeh2009"), o);
  ASSERT_TRUE(gated.ok()) << gated.status().message();
  EXPECT_EQ(gated->verdict, "end_stop_bounce") << DiagnosisReport(*gated);

  // A bounce with a 0.5 % softer spring and nothing else: the bounce alone leaves less than a significant gap, and no partner is taken for the drift.
  model::PlantParams drifted = With("end_stop_bounce", {{"e", 0.49}});
  drifted.k_N_per_m *= 0.995;
  o.evidence_below_gate = true;
  auto d2 = Diagnose(Session(drifted), *model::Preset("taghizadeh2009"), o);
  ASSERT_TRUE(d2.ok()) << d2.status().message();
  EXPECT_EQ(d2->verdict, "end_stop_bounce") << DiagnosisReport(*d2);
  // ... and the search beside it did run, below the gate.
  bool considered = false;
  for (const auto& a : d2->additions)
    if (a.before_A <= kSignificance * d2->noise_floor_A) considered = true;
  EXPECT_TRUE(considered) << DiagnosisReport(*d2);
}

// A resistance change beside an effect (ResistanceBesideAnEffect): every structural candidate frees R, so the
// change is fitted inside the effect's own R. A 6 % colder-reading coil beside eddy currents is named beside them;
// a 2 % one beside strong eddy currents is dominated by them (the gapbench README's labelling rule) and is
// reported as drift, not named. Switched off, the 6 % change is the effect alone.
TEST(Attribution, AResistanceChangeBesideAnEffectIsNamedWhenTheEffectDoesNotDominateIt) {
  const std::vector<std::string> names = {"param:R", "param:k", "eddy_currents", "supply_resistance", "sensor_gain"};
  DiagnoseOptions o = Options(names, true);
  o.detection_limits = false;
  o.max_effects = 2;
  model::PlantParams truth = With("eddy_currents", {{"R_p", 600.0}});
  truth.R_ohm *= 1.06;
  const auto ds = Session(truth);
  auto d = Diagnose(ds, *model::Preset("taghizadeh2009"), o);
  ASSERT_TRUE(d.ok()) << d.status().message();
  EXPECT_EQ(VerdictMembers(d->verdict), (std::vector<std::string>{"eddy_currents", "param:R"})) << DiagnosisReport(*d);
  o.resistance_beside_effect = false;
  auto off = Diagnose(ds, *model::Preset("taghizadeh2009"), o);
  ASSERT_TRUE(off.ok()) << off.status().message();
  EXPECT_EQ(off->verdict, "eddy_currents") << DiagnosisReport(*off);

  o.resistance_beside_effect = true;
  model::PlantParams slight = With("eddy_currents", {{"R_p", 150.0}});
  slight.R_ohm *= 1.02;
  auto d2 = Diagnose(Session(slight), *model::Preset("taghizadeh2009"), o);
  ASSERT_TRUE(d2.ok()) << d2.status().message();
  EXPECT_EQ(d2->verdict, "eddy_currents") << DiagnosisReport(*d2);
  bool reported = false;
  for (const auto& drift : d2->nuisance) reported = reported || drift.param == "R";
  EXPECT_TRUE(reported) << DiagnosisReport(*d2);
}

// A drifted parameter that the holdout runs show by itself (a 10 % soft spring beside eddy currents) is a cause
// in the verdict; one below what the runs could show alone is reported as drift.
TEST(Attribution, ADriftTheRunsShowByItselfIsACause) {
  model::PlantParams truth = With("eddy_currents", {{"R_p", 300.0}});
  truth.k_N_per_m *= 0.9;
  const auto ds = Session(truth);
  DiagnoseOptions o = Options({"param:R", "param:k", "param:m", "eddy_currents", "supply_resistance"}, true);
  o.detection_limits = false;
  auto d = Diagnose(ds, *model::Preset("taghizadeh2009"), o);
  ASSERT_TRUE(d.ok()) << d.status().message();
  EXPECT_EQ(VerdictMembers(d->verdict), (std::vector<std::string>{"eddy_currents", "param:k"})) << DiagnosisReport(*d);
  EXPECT_TRUE(d->nuisance.empty());
  EXPECT_NEAR(d->ranking.front().params.at("k"), 9000.0, 300.0);
  ASSERT_EQ(d->members.size(), 2u);
  // A 1 % soft spring: below what these runs show by itself; the verdict is the effect alone.
  model::PlantParams slight = With("eddy_currents", {{"R_p", 300.0}});
  slight.k_N_per_m *= 0.99;
  auto d2 = Diagnose(Session(slight), *model::Preset("taghizadeh2009"), o);
  ASSERT_TRUE(d2.ok()) << d2.status().message();
  EXPECT_EQ(d2->verdict, "eddy_currents") << DiagnosisReport(*d2);
}

}  // namespace
}  // namespace vb::gap

namespace vb::gap {
namespace {

// The residual's integrated autocorrelation time: 1 for white noise, (1 + rho) / (1 - rho) for a first-order
// autoregression, pooled over runs.
TEST(AdditionRule, AutocorrelationTimeOfWhiteAndCorrelatedResiduals) {
  std::mt19937 rng(5);
  std::normal_distribution<double> n01(0.0, 1.0);
  std::vector<std::vector<double>> white(2), ar(2);
  for (int r = 0; r < 2; ++r) {
    double x = 0.0;
    for (int k = 0; k < 20000; ++k) {
      white[r].push_back(n01(rng));
      x = 0.9 * x + n01(rng);
      ar[r].push_back(x);
    }
  }
  EXPECT_NEAR(IntegratedAutocorrelationTime(white), 1.0, 0.15);
  EXPECT_NEAR(IntegratedAutocorrelationTime(ar), 19.0, 4.0);
  EXPECT_EQ(IntegratedAutocorrelationTime({}), 1.0);
}

// The rule on residuals built to the two cases it must tell apart. The smaller model leaves a smooth structure
// (6 mA, one period over each 80 ms run) in 2 mA of noise. An addition that only patches that structure (takes 40 % of it: what a second
// effect does to another effect's form error) leaves a structured residual, worth a handful of independent
// samples: refused, although it removes a significant energy. A real second cause leaves the noise: accepted.
// And nothing is added to a model that leaves no significant gap.
TEST(AdditionRule, RefusesAPatchOfFormErrorAndAcceptsARealSecondCause) {
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0.0, 2e-3);
  const double floor = 2e-3;
  std::vector<std::vector<double>> smaller(2), patch(2), real(2);
  for (int r = 0; r < 2; ++r)
    for (int k = 0; k < 4000; ++k) {
      const double t = k * 2e-5;
      const double structure = 6e-3 * std::sin(2.0 * M_PI * t / 0.08 + r);
      const double e = noise(rng);
      smaller[r].push_back(structure + e);
      patch[r].push_back(0.6 * structure + e);
      real[r].push_back(e);
    }
  auto rms = [](const std::vector<std::vector<double>>& x) {
    double s = 0.0, n = 0.0;
    for (const auto& r : x)
      for (double v : r) {
        s += v * v;
        n += 1.0;
      }
    return std::sqrt(s / n);
  };
  auto n_eff = [](const std::vector<std::vector<double>>& x) {
    return 8000.0 / IntegratedAutocorrelationTime(x);
  };
  const double before = rms(smaller);
  ASSERT_GT(before, kSignificance * floor);
  // The patch removes more than a significant gap's energy, which the earlier rules counted (it also would not
  // have halved the remainder; the specific-addition rule would have taken it had nothing else patched as much).
  EXPECT_GT(before * before - rms(patch) * rms(patch), (kSignificance * kSignificance - 1.0) * floor * floor);
  EXPECT_LT(n_eff(patch), 40.0);
  EXPECT_FALSE(AddsACause(before, rms(patch), n_eff(patch), kAdditionEvidence))
      << AdditionEvidence(before, rms(patch), n_eff(patch));
  EXPECT_GT(n_eff(real), 5000.0);
  EXPECT_TRUE(AddsACause(before, rms(real), n_eff(real), kAdditionEvidence))
      << AdditionEvidence(before, rms(real), n_eff(real));
  // An addition that only fits noise makes the holdout runs worse: no evidence, however many samples.
  EXPECT_FALSE(AddsACause(floor, 1.01 * floor, 8000.0, kAdditionEvidence));
  // A weak real cause beside a strong one (1.2 mA left in 2 mA of noise, less than a significant gap by itself)
  // is plain in 8000 white samples.
  EXPECT_TRUE(AddsACause(std::hypot(1.2e-3, floor), floor, 8000.0, kAdditionEvidence));
}

// Parsimony (docs/gap.md, "Parsimony: a larger model must earn its parameters"): the nested F-test counts every
// extra free parameter, and the larger model's residual's independent samples.
TEST(ParsimonyRule, CountsTheExtraParametersAndTheIndependentSamples) {
  // practice3 m03 as measured: param:R (1 parameter) leaves 1.447 mA of a 1011-sample holdout run;
  // coulomb_friction+param:delta (R, F_c, F_s, delta) leaves 0.921 mA, structured over 47 samples; 5 pairs were
  // compared. F 8.4 on (3, 17.5): p 0.0012 against 0.002, so the test alone takes it (what refuses it is that R
  // alone does as well, RAloneDoesAsWell; Practice3/MovingValveWithheld checks the verdict).
  const Parsimony m03 = ParsimonyTest(1.447e-3, 1, 0.921e-3, 4, 47.0, 1011, 5);
  EXPECT_NEAR(m03.samples, 21.5, 0.1);
  EXPECT_NEAR(m03.level, 0.002, 1e-12);
  EXPECT_NEAR(m03.p_value, 0.0012, 0.0002);
  // The same step structured over 100 samples (10 independent) does not carry 3 more parameters.
  const Parsimony structured = ParsimonyTest(1.447e-3, 1, 0.921e-3, 4, 100.0, 1011, 5);
  EXPECT_FALSE(structured.passes) << "F " << structured.f << " p " << structured.p_value;
  // Nor a small step with 12 more parameters on white residuals, out of 20 compared.
  EXPECT_FALSE(ParsimonyTest(1.447e-3, 1, 1.44e-3, 13, 1.0, 1011, 20).passes);

  // A real second cause (two more parameters) whose signature is a 6 mA structure in 2 mA of noise over two 80 ms
  // holdout runs leaves the noise: taken, whether it rings or swings slowly.
  auto residuals = [](double periods_per_run, bool with_cause) {
    std::mt19937 rng(11);
    std::normal_distribution<double> noise(0.0, 2e-3);
    std::vector<std::vector<double>> x(2);
    for (int r = 0; r < 2; ++r)
      for (int k = 0; k < 4000; ++k)
        x[r].push_back((with_cause ? 6e-3 * std::sin(2.0 * M_PI * periods_per_run * k / 4000.0 + r) : 0.0) +
                       noise(rng));
    return x;
  };
  auto rms = [](const std::vector<std::vector<double>>& x) {
    double s = 0.0, n = 0.0;
    for (const auto& r : x)
      for (double v : r) s += v * v, n += 1.0;
    return std::sqrt(s / n);
  };
  for (double periods : {20.0, 1.0}) {
    const auto before = residuals(periods, true), after = residuals(periods, false);
    const Parsimony p = ParsimonyTest(rms(before), 2, rms(after), 4, IntegratedAutocorrelationTime(after), 8000, 4);
    EXPECT_TRUE(p.passes) << periods << " periods: F " << p.f << " on " << p.samples << " samples, p " << p.p_value;
  }

  // Worse on the holdout runs, or fewer independent samples than the larger model has parameters: not taken.
  EXPECT_FALSE(ParsimonyTest(2e-3, 1, 2.1e-3, 2, 1.0, 8000, 1).passes);
  EXPECT_FALSE(ParsimonyTest(10e-3, 1, 1e-3, 4, 500.0, 2000, 1).passes);
  // Bonferroni: the level is shared by the larger models the best was chosen from.
  EXPECT_NEAR(ParsimonyTest(2e-3, 1, 1e-3, 2, 1.0, 100, 10).level, kParsimonyLevel / 10.0, 1e-15);
  // Level 1 switches the test off (before/after figures).
  EXPECT_TRUE(ParsimonyTest(2e-3, 1, 2.1e-3, 2, 1.0, 8000, 1, 1.0).passes);
}

}  // namespace
}  // namespace vb::gap
