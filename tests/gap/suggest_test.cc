// The next experiment, in a closed loop on the emulator (docs/gap.md, "The next experiment"): a session whose
// effect the diagnosis cannot tell from another, the suggestion, the suggested spec run on the emulator with
// the effect on (the bench), its runs added to the session, and the diagnosis again.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <random>

#include "../common/run_command.h"

#include "experiment/runner.h"
#include "experiment/spec.h"
#include "gap/attribution.h"
#include "gap/diagnose.h"
#include "gap/suggest.h"
#include "hw/emulated_bench.h"
#include "synthetic_session.h"

namespace vb::gap {
namespace {

std::vector<Candidate> Pick(const std::vector<std::string>& names) {
  std::vector<Candidate> out;
  for (const auto& c : DefaultCandidates(*model::Preset("taghizadeh2009")))
    if (std::find(names.begin(), names.end(), c.name) != names.end()) out.push_back(c);
  return out;
}

DiagnoseOptions Options() {
  DiagnoseOptions o;
  // A softer spring or a smaller preload: both lower k (x + delta), and the session's runs hardly tell which.
  o.candidates = Pick({"param:k", "param:delta", "param:R"});
  o.try_combinations = false;
  o.detection_limits = false;
  o.overlay_points = 10;
  return o;
}

// Runs the suggested spec on the emulator with the truth as its plant and adds every run to the session as a
// holdout run (they test the contenders' predictions), recorded through the same 2 mA chain.
void RunSuggestion(const std::string& spec_json, const std::vector<std::pair<std::string, double>>& truth_params,
                   Dataset* ds) {
  auto spec = experiment::ParseSpecJson(spec_json);
  ASSERT_TRUE(spec.ok()) << spec.status().message();
  for (const auto& [k, v] : truth_params) (*spec->mutable_bench()->mutable_model()->mutable_params())[k] = v;
  auto points = experiment::ExpandRuns(*spec);
  ASSERT_TRUE(points.ok()) << points.status().message();
  std::mt19937 rng(99);
  std::normal_distribution<double> noise(0.0, 2e-3);
  double t0 = ds->runs.back().t_start_s + 1.0;
  for (const auto& p : *points) {
    auto e = experiment::BuildExperiment(p.spec);
    ASSERT_TRUE(e.ok()) << e.status().message();
    hw::EmulatedBench bench(experiment::EmulatedBenchFor(*e));
    experiment::Trace trace;
    auto summary = experiment::Runner::Run(*e, bench, &trace);
    ASSERT_TRUE(summary.ok()) << summary.message;
    RunData r;
    r.id = p.spec.name();
    r.supply_V = p.spec.conditions().supply_v();
    r.supply_pressure_Pa = p.spec.conditions().supply_pressure_pa();
    r.t_start_s = t0;
    r.split = Split::kHoldout;
    r.sample_period_s = trace.sample_period_s;
    r.t_s = trace.t_s;
    r.gate = trace.gate;
    for (double i : trace.i_A) r.i_A.push_back(i + noise(rng));
    t0 += trace.t_s.back() + 1.0;
    ds->runs.push_back(std::move(r));
  }
}

TEST(Suggest, TheSuggestedRunsResolveAnAmbiguityInAClosedLoop) {
  model::PlantParams truth = *model::Preset("taghizadeh2009");
  const double k_true = 0.9 * truth.k_N_per_m;
  truth.k_N_per_m = k_true;
  Dataset ds = Session(truth);
  const auto nominal = *model::Preset("taghizadeh2009");
  auto before = Diagnose(ds, nominal, Options());
  ASSERT_TRUE(before.ok()) << before.status().message();
  ASSERT_TRUE(before->significant);
  // The premise: these runs leave the two confusable.
  const bool ambiguous = std::find(before->confusable.begin(), before->confusable.end(), "param:delta") !=
                             before->confusable.end() ||
                         std::find(before->confusable.begin(), before->confusable.end(), "param:k") !=
                             before->confusable.end();
  ASSERT_TRUE(ambiguous) << "verdict " << before->verdict << ", margin " << before->margin_A;

  auto s = SuggestNextRuns(ds, nominal, *before);
  ASSERT_TRUE(s.ok()) << s.status().message();
  ASSERT_GE(s->contenders.size(), 2u);
  ASSERT_FALSE(s->runs.empty()) << s->note;
  // The best design separates the contenders by more than the session's runs do, and by more than the noise.
  EXPECT_GT(s->runs.front().separation_sigma, s->current_separation_sigma);
  EXPECT_GT(s->runs.front().separation_sigma, kSignificance);
  const std::string report = SuggestionReport(*s);
  EXPECT_NE(report.find("sigma"), std::string::npos);

  RunSuggestion(SuggestionSpecJson(*s, "next", "taghizadeh2009"), {{"k", k_true}}, &ds);
  auto after = Diagnose(ds, nominal, Options());
  ASSERT_TRUE(after.ok()) << after.status().message();
  EXPECT_EQ(after->verdict, "param:k");
  EXPECT_TRUE(after->confusable.empty()) << "still confusable with " << after->confusable.front();
  EXPECT_NEAR(after->ranking.front().params.at("k"), k_true, 0.02 * k_true);
}

// The control for the test above: a run like those the session already has (a 20 ms step at 24 V) leaves the
// ambiguity where it was, so it is the suggested design, not any extra run, that resolves it.
TEST(Suggest, ARunLikeTheSessionsOwnLeavesTheAmbiguity) {
  model::PlantParams truth = *model::Preset("taghizadeh2009");
  const double k_true = 0.9 * truth.k_N_per_m;
  truth.k_N_per_m = k_true;
  Dataset ds = Session(truth);
  const auto nominal = *model::Preset("taghizadeh2009");
  Suggestion same;
  same.contenders = {"param:k", "param:delta"};
  same.sample_rate_Hz = 1.0 / ds.runs.front().sample_period_s;
  Design d;
  d.supply_V = 24.0;
  d.supply_pressure_Pa = 3e5;
  d.hold_s = 0.02;
  same.runs.push_back({d, 0.0, ""});
  RunSuggestion(SuggestionSpecJson(same, "same", "taghizadeh2009"), {{"k", k_true}}, &ds);
  auto after = Diagnose(ds, nominal, Options());
  ASSERT_TRUE(after.ok()) << after.status().message();
  EXPECT_FALSE(after->confusable.empty()) << "verdict " << after->verdict;
}

// The same loop as a user runs it, with benchctl alone: diagnose p09 (a 15 % soft spring, confusable with a
// smaller preload) --suggest; run the suggested spec on the local emulator with the valve's true spring; diagnose
// p09 again with those runs added (--add-runs): param:k, and nothing confusable.
TEST(Suggest, TheLoopWithBenchctlAlone) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::path(::testing::TempDir()) / ("vb-suggest-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string bc = std::string(VB_BENCHCTL), db = (dir / "store.db").string();
  const std::string p09 = std::string(VB_SHARED_DIR) + "/gapbench/practice/p09";
  auto first = testing::RunCommand(bc + " diagnose " + p09 + " --suggest " + (dir / "next.json").string() + " 2>&1");
  ASSERT_EQ(first.exit_code, 0) << first.out;
  EXPECT_NE(first.out.find("next experiment (to separate param:k param:delta"), std::string::npos) << first.out;
  // The bench: the emulator with the valve's true spring (the gapbench label: k = 8500 N/m).
  nlohmann::json spec = nlohmann::json::parse(std::ifstream(dir / "next.json"));
  spec["bench"]["model"]["params"] = {{"k", 8500.0}};
  std::ofstream(dir / "bench.json") << spec.dump();
  auto ran = testing::RunCommand(bc + " run --local --db " + db + " " + (dir / "bench.json").string() + " --json");
  ASSERT_EQ(ran.exit_code, 0) << ran.out;
  std::string ids;
  for (const auto& r : nlohmann::json::parse(ran.out)) ids += (ids.empty() ? "" : ",") + std::to_string(r["id"].get<long>());
  auto again = testing::RunCommand(bc + " diagnose " + p09 + " --add-runs " + ids + " --local --db " + db + " --json");
  ASSERT_EQ(again.exit_code, 0) << again.out;
  const auto d = nlohmann::json::parse(again.out);
  EXPECT_EQ(d["verdict"], "param:k");
  EXPECT_TRUE(d["confusable"].empty()) << d["confusable"].dump();
  int holdout = 0;
  for (const auto& r : d["runs"]) holdout += r["split"] == "holdout" && r["id"].get<std::string>().find("next-experiment") != std::string::npos;
  EXPECT_EQ(holdout, static_cast<int>(nlohmann::json::parse(ran.out).size()));
  fs::remove_all(dir);
}

TEST(Suggest, NothingToSeparateWhenTheVerdictStandsAlone) {
  Dataset ds = Session(With("supply_resistance", {{"R_s", 0.8}}));
  DiagnoseOptions o;
  o.candidates = Pick({"param:R", "supply_resistance"});
  o.try_combinations = false;
  o.detection_limits = false;
  auto d = Diagnose(ds, *model::Preset("taghizadeh2009"), o);
  ASSERT_TRUE(d.ok()) << d.status().message();
  ASSERT_EQ(d->verdict, "supply_resistance");
  auto s = SuggestNextRuns(ds, *model::Preset("taghizadeh2009"), *d);
  ASSERT_TRUE(s.ok());
  EXPECT_TRUE(s->runs.empty());
  EXPECT_NE(s->note.find("nothing to separate"), std::string::npos);
}

TEST(Suggest, TheGateOfADesignRestsThenPulsesThenReleases) {
  Design d;
  d.rest_s = 0.01;
  d.pwm_Hz = 100.0;
  d.duty = 0.25;
  d.hold_s = 0.02;
  d.tail_s = 0.01;
  const auto g = DesignGate(d, 1e-4);
  ASSERT_EQ(g.size(), 401u);
  int on = 0;
  for (std::size_t k = 0; k < g.size(); ++k) {
    const double t = static_cast<double>(k) * 1e-4;
    if (t < 0.01 - 1e-12 || t >= 0.03 - 1e-12) {
      EXPECT_EQ(g[k], 0) << "at " << t;
    }
    on += g[k];
  }
  EXPECT_EQ(on, 50);  // two periods of 10 ms at 25 %
}

}  // namespace
}  // namespace vb::gap
