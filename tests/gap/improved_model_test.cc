// The one improved-model builder (gap/improved_model.h) that `benchctl diagnose --model-out` and the server's
// DiagnoseRuns share.
#include <gtest/gtest.h>

#include "gap/improved_model.h"

namespace vb::gap {
namespace {

Diagnosis WithVerdict() {
  Diagnosis d;
  d.verdict = "eddy_currents+param:R";
  d.verdict_kind = VerdictKind::kCombination;
  Candidate c;
  c.name = d.verdict;
  c.effects = {"eddy_currents"};
  c.fixed = {{"thermal.T_ref_C", 21.0}};
  d.candidates = {c};
  CandidateResult r;
  r.name = c.name;
  r.params = {{"R", 29.5}, {"eddy_currents.R_p", 120.0}, {"driver.diode_drop_V", 0.9}};
  d.ranking = {r};
  d.chosen = 0;
  return d;
}

TEST(ImprovedModel, NominalPlusTheVerdictsFittedValues) {
  valvebench::v1::ModelSpec nominal;
  nominal.set_preset("taghizadeh2009");
  model::DriverParams driver;
  driver.diode_drop_V = 0.7;
  auto m = ImprovedModel(WithVerdict(), nominal, driver, "a test on runs 1,2");
  ASSERT_TRUE(m.ok()) << m.status().message();
  EXPECT_EQ(m->preset(), "taghizadeh2009");
  EXPECT_DOUBLE_EQ(m->params().at("R"), 29.5);
  ASSERT_GE(m->effects_size(), 2);
  EXPECT_EQ(m->effects(0).name(), "eddy_currents");
  EXPECT_DOUBLE_EQ(m->effects(0).params().at("R_p"), 120.0);
  EXPECT_EQ(m->effects(1).name(), "thermal") << "a fixed value's effect is added with it";
  EXPECT_DOUBLE_EQ(m->effects(1).params().at("T_ref_C"), 21.0);
  EXPECT_DOUBLE_EQ(m->identified_driver().params().at("diode_drop_V"), 0.9) << "the fitted drop, not the base";
  EXPECT_EQ(m->description(), "nominal + eddy_currents+param:R, fitted by a test on runs 1,2");
  EXPECT_NE(ModelSpecJson(*m).find("\"R_p\": 120"), std::string::npos) << ModelSpecJson(*m);
}

TEST(ImprovedModel, NoneGivesTheNominalAndUnknownGivesNone) {
  valvebench::v1::ModelSpec nominal;
  nominal.set_preset("taghizadeh2009");
  Diagnosis none;
  none.verdict = "none";
  none.verdict_kind = VerdictKind::kNone;
  auto m = ImprovedModel(none, nominal, {}, "x");
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->effects_size(), 0);
  EXPECT_EQ(m->params_size(), 0);
  Diagnosis unknown;
  unknown.verdict = "unknown";
  unknown.verdict_kind = VerdictKind::kUnknown;
  EXPECT_EQ(ImprovedModel(unknown, nominal, {}, "x").status().code(), StatusCode::kFailedPrecondition);
}

TEST(VerdictKinds, OneFormatterEachWay) {
  for (VerdictKind k : {VerdictKind::kNone, VerdictKind::kEffect, VerdictKind::kParameter, VerdictKind::kCombination,
                        VerdictKind::kEitherOf, VerdictKind::kUnknown}) {
    auto back = ParseVerdictKind(VerdictKindName(k));
    ASSERT_TRUE(back.ok()) << VerdictKindName(k);
    EXPECT_EQ(*back, k);
  }
  for (CauseKind k : {CauseKind::kEffect, CauseKind::kParameter, CauseKind::kCombination}) {
    EXPECT_EQ(*ParseCauseKind(CauseKindName(k)), k);
    EXPECT_STREQ(VerdictKindName(VerdictKindOf(k)), CauseKindName(k));
  }
  for (Disqualification w : {Disqualification::kNone, Disqualification::kEffectVanished, Disqualification::kSaturatedFit,
                             Disqualification::kRAloneDoesAsWell, Disqualification::kMemberVanished,
                             Disqualification::kNotDecisive})
    EXPECT_EQ(*ParseDisqualification(DisqualificationName(w)), w);
  EXPECT_EQ(ParseVerdictKind("maybe").status().code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(ParseCauseKind("param").ok());
}

TEST(VerdictKinds, CandidatesDeclareTheirKindAndPairsAreCombinations) {
  const Candidate r = ParamCandidate("R", {"R", 20.0, 40.0, 28.5, false});
  EXPECT_EQ(r.name, "param:R");
  EXPECT_EQ(r.kind, CauseKind::kParameter);
  const Candidate eddy{"eddy_currents", {"eddy_currents"}, {{"eddy_currents.R_p", 10.0, 1e5, 500.0, true, 1e5}}};
  EXPECT_EQ(eddy.kind, CauseKind::kEffect);
  const Candidate both = PairCandidate(eddy, r);
  EXPECT_EQ(both.kind, CauseKind::kCombination);
  EXPECT_EQ(Members(both), (std::vector<std::string>{"eddy_currents", "param:R"}));
  // A name is for people: an effect whose name looks like a parameter's is still an effect.
  const Candidate odd{"param:looking_effect", {"supply_resistance"}, {}};
  EXPECT_EQ(odd.kind, CauseKind::kEffect);
  // The diagnosis JSON says the kind beside the verdict's name.
  Diagnosis d = WithVerdict();
  EXPECT_NE(DiagnosisJson(d).find("\"verdict_kind\": \"combination\""), std::string::npos) << DiagnosisJson(d);
}

}  // namespace
}  // namespace vb::gap
