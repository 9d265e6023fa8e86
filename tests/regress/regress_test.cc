// Suites, the spread-aware comparison, baselines as JSON, JUnit XML and cron schedules (regress/).
#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <string>

#include "experiment/spec.h"
#include "regress/compare.h"
#include "regress/cron.h"
#include "regress/suite.h"

namespace vb::regress {
namespace {

namespace v1 = valvebench::v1;

// A short PI current-control task on the emulator (inline spec).
std::string Entry(const std::string& name, const std::string& extra = "") {
  return R"({"name": ")" + name + R"(", "spec": {
      "bench": {"model": {"preset": "taghizadeh2009"}},
      "conditions": {"supply_V": 24, "supply_pressure_Pa": 400000},
      "reference": {"constant": {"value": 0.5}},
      "controller": {"pi_current": {}},
      "duration_s": 0.01, "recording": {"rate_Hz": 20000}})" +
         extra + "}";
}

std::string SuiteJson(const std::string& entries, const std::string& extra = "") {
  return R"({"name": "t", "tolerances": [{"metric": "rmse", "relative": 0.1}], "experiments": [)" + entries + "]" +
         extra + "}";
}

void ExpectError(const std::string& json, const std::string& needle, StatusCode code = StatusCode::kInvalidArgument) {
  auto s = ParseSuite(json, "");
  ASSERT_FALSE(s.ok()) << "accepted: " << json;
  EXPECT_EQ(s.status().code(), code);
  EXPECT_NE(s.status().message().find(needle), std::string::npos) << s.status().message();
}

TEST(SuiteTest, ParsesAndResolvesDefaults) {
  auto s = ParseSuite(SuiteJson(Entry("pi", R"(, "repeats": 3)")), "");
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_EQ(s->suite.experiments(0).bench_class(), "emulated:taghizadeh2009");
  EXPECT_EQ(s->suite.experiments(0).spec().name(), "pi");
  EXPECT_EQ(s->suite.experiments(0).spec().repeats(), 3u);
  auto tols = TolerancesFor(s->suite, 0);
  ASSERT_EQ(tols.size(), 1u);
  EXPECT_EQ(tols[0].direction, v1::LOWER_IS_BETTER);  // rmse: lower is better by default
  EXPECT_DOUBLE_EQ(NoiseSigmas(s->suite), 3.0);
}

TEST(SuiteTest, BadInputNamesTheField) {
  ExpectError(R"({"experiments": []})", "name:");
  ExpectError(R"({"name": "x", "experiments": []})", "experiments:");
  ExpectError(R"({"name": "x", "bogus": 1, "experiments": []})", "bogus");
  ExpectError(SuiteJson(R"({"name": "a"})"), "experiments[0]: give exactly one of spec_file and spec");
  ExpectError(SuiteJson(Entry("a") + "," + Entry("a")), "experiments[1].name: duplicate case name 'a'");
  ExpectError(SuiteJson(Entry("a", R"(, "bench_class": "emulated:lunge2013")")),
              "experiments[0].bench_class: 'emulated:lunge2013' but the spec runs on 'emulated:taghizadeh2009'");
  ExpectError(SuiteJson(Entry("a", R"(, "tolerances": [{"metric": "rsme"}])")),
              "experiments[0].tolerances[0].metric: unknown metric 'rsme'");
  ExpectError(SuiteJson(Entry("a", R"(, "tolerances": [{"metric": "rmse", "relative": -1}])")),
              "experiments[0].tolerances[0].relative: must be finite and >= 0");
  ExpectError(SuiteJson(Entry("a", R"(, "jitter": [{"field": "conditions.supply_volts", "relative_sd": 0.01}])")),
              "jitter[0].field");
  ExpectError(SuiteJson(Entry("a", R"(, "jitter": [{"field": "conditions.supply_V", "relative_sd": -0.01}])")),
              "experiments[0].jitter[0].relative_sd");
  ExpectError(SuiteJson(Entry("a"), R"(, "noise_sigmas": -1)"), "noise_sigmas: must be finite and >= 0");
  ExpectError(SuiteJson(R"({"name": "a", "spec_file": "/nonexistent/spec.json"})"), "experiments[0].spec_file",
              StatusCode::kNotFound);
  // A spec that does not build is refused before anything runs, with the spec's own field path.
  ExpectError(SuiteJson(Entry("a", "").replace(Entry("a").find("\"supply_V\": 24"), 14, "\"supply_V\": -1")),
              "conditions.supply_V");
  // No metric to compare anywhere.
  ExpectError(R"({"name": "t", "experiments": [)" + Entry("a") + "]}", "experiments[0].tolerances: no metric");
}

TEST(SuiteTest, JitterIsSeededBoundedAndPerRun) {
  auto s = ParseSuite(
      SuiteJson(Entry("pi", R"(, "repeats": 4, "jitter": [{"field": "conditions.supply_V", "relative_sd": 0.01},
                                                     {"field": "perturbation.param_scale[R]", "relative_sd": 0.02}])")),
      "");
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  auto a = ExpandSuite(s->suite, 7), b = ExpandSuite(s->suite, 7), c = ExpandSuite(s->suite, 8);
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  ASSERT_EQ(a->size(), 4u);
  std::set<double> supplies;
  for (size_t k = 0; k < a->size(); ++k) {
    const double v = (*a)[k].spec.conditions().supply_v();
    EXPECT_EQ(v, (*b)[k].spec.conditions().supply_v());        // same seed: bit-identical
    EXPECT_NE(v, (*c)[k].spec.conditions().supply_v());        // another seed: other values
    EXPECT_LE(std::fabs(v / 24.0 - 1.0), 0.03 + 1e-12);        // clipped at 3 sd
    const double r = (*a)[k].spec.perturbation().param_scale().at("R");
    EXPECT_LE(std::fabs(r - 1.0), 0.06 + 1e-12);
    EXPECT_NE(r, 1.0);
    supplies.insert(v);
    EXPECT_EQ((*a)[k].case_name, "pi");  // repeats share the case
    EXPECT_TRUE(experiment::BuildExperiment((*a)[k].spec).ok());
  }
  EXPECT_EQ(supplies.size(), 4u);  // every repeat differs
}

TEST(SuiteTest, CaseNamesKeepVariantsAndSweepsApart) {
  auto s = ParseSuite(SuiteJson(Entry("m", R"(, "repeats": 2)").replace(
                          Entry("m").find("\"duration_s\""), 0,
                          R"("sweep": [{"field": "conditions.supply_V", "values": [20, 24]}], )")),
                      "");
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  auto runs = ExpandSuite(s->suite, 1);
  ASSERT_TRUE(runs.ok());
  ASSERT_EQ(runs->size(), 4u);
  EXPECT_EQ((*runs)[0].case_name, "m sweep:conditions.supply_V=20");
  EXPECT_EQ((*runs)[1].case_name, "m sweep:conditions.supply_V=20");
  EXPECT_EQ((*runs)[2].case_name, "m sweep:conditions.supply_V=24");
  // The identity is fields: repeats share the case, the display name adds the repeat.
  EXPECT_EQ((*runs)[3].key.sweep, (std::vector<SweepCoordinate>{{"conditions.supply_V", 24.0}}));
  EXPECT_EQ((*runs)[3].key.repeat, 1);
  EXPECT_EQ((*runs)[3].key.DisplayName(), "m sweep:conditions.supply_V=24 repeat:1");
}

ResolvedTolerance Tol(const std::string& metric, double abs, double rel, v1::Direction d = v1::LOWER_IS_BETTER) {
  return {metric, abs, rel, d};
}

TEST(JudgeTest, ToleranceAndNoiseBandDecide) {
  const Stat base{1.0, 0.0, 3};
  // 4 % worse with a 5 % tolerance: unchanged; 6 % worse: regressed; 6 % better: improved.
  Stat now{1.04, 0.0, 3};
  EXPECT_EQ(Judge("c", Tol("rmse", 0, 0.05), 3, &base, &now).verdict, Verdict::kUnchanged);
  now.mean = 1.06;
  auto f = Judge("c", Tol("rmse", 0, 0.05), 3, &base, &now);
  EXPECT_EQ(f.verdict, Verdict::kRegressed);
  EXPECT_NEAR(f.delta, 0.06, 1e-12);
  EXPECT_NEAR(f.allowed, 0.05, 1e-12);
  EXPECT_NE(f.message.find("rmse"), std::string::npos);
  EXPECT_NE(f.message.find("1 -> now 1.06"), std::string::npos) << f.message;
  now.mean = 0.94;
  EXPECT_EQ(Judge("c", Tol("rmse", 0, 0.05), 3, &base, &now).verdict, Verdict::kImproved);
  // The same 6 % is inside the noise when the repeats scatter by 1.5 % each: 3 * sqrt(2) * 0.015 = 0.064.
  const Stat noisy_base{1.0, 0.015, 3};
  Stat noisy_now{1.06, 0.015, 3};
  f = Judge("c", Tol("rmse", 0, 0.0), 3, &noisy_base, &noisy_now);
  EXPECT_EQ(f.verdict, Verdict::kUnchanged);
  EXPECT_NEAR(f.noise, 3 * std::sqrt(2.0) * 0.015, 1e-12);
  // Absolute tolerance wins when larger than the relative one.
  now.mean = 1.2;
  EXPECT_EQ(Judge("c", Tol("rmse", 0.25, 0.05), 3, &base, &now).verdict, Verdict::kUnchanged);
}

TEST(JudgeTest, DirectionsNewAndMissing) {
  const Stat base{10.0, 0.0, 1};
  Stat up{11.0, 0.0, 1};
  EXPECT_EQ(Judge("c", Tol("x", 0, 0.05, v1::HIGHER_IS_BETTER), 3, &base, &up).verdict, Verdict::kImproved);
  EXPECT_EQ(Judge("c", Tol("x", 0, 0.05, v1::LOWER_IS_BETTER), 3, &base, &up).verdict, Verdict::kRegressed);
  EXPECT_EQ(Judge("c", Tol("x", 0, 0.05, v1::BOTH), 3, &base, &up).verdict, Verdict::kRegressed);
  Stat down{9.0, 0.0, 1};
  EXPECT_EQ(Judge("c", Tol("x", 0, 0.05, v1::BOTH), 3, &base, &down).verdict, Verdict::kRegressed);
  EXPECT_EQ(Judge("c", Tol("x", 0, 0.05, v1::HIGHER_IS_BETTER), 3, &base, &down).verdict, Verdict::kRegressed);
  EXPECT_EQ(Judge("c", Tol("x", 0, 0.05), 3, nullptr, &up).verdict, Verdict::kNew);
  const Stat none{0.0, 0.0, 0};
  auto f = Judge("c", Tol("x", 0, 0.05), 3, &base, &none);
  EXPECT_EQ(f.verdict, Verdict::kRegressed);
  EXPECT_NE(f.message.find("no value"), std::string::npos);
}

LoadedSuite TwoMetricSuite() {
  auto s = ParseSuite(R"({"name": "t", "tolerances": [{"metric": "rmse", "relative": 0.1},
      {"metric": "switches", "absolute": 2}], "experiments": [)" + Entry("pi") + "," + Entry("hy") + "]}", "");
  EXPECT_TRUE(s.ok()) << s.status().ToString();
  return *s;
}

TEST(CompareTest, SummarisesRepeatsAndFindsTheRegression) {
  const LoadedSuite s = TwoMetricSuite();
  Baseline b;
  b.name = "main";
  b.version = 2;
  b.cases["pi"]["rmse"] = {0.001, 0.0, 2};
  b.cases["pi"]["switches"] = {100, 0.0, 2};
  b.cases["hy"]["rmse"] = {0.006, 0.0, 1};
  b.cases["other-suite-case"]["rmse"] = {1, 0, 1};  // not this suite's: ignored
  std::vector<RunMetrics> runs = {
      {1, "pi repeat:0", "pi", true, "", {{"rmse", 0.0010}, {"switches", 100}}},
      {2, "pi repeat:1", "pi", true, "", {{"rmse", 0.0030}, {"switches", 101}}},  // mean rmse 0.002: doubled
      {3, "hy", "hy", true, "", {{"rmse", 0.006}, {"switches", 7}}},
  };
  const Measured m = Summarise(runs);
  EXPECT_NEAR(m.stats.at("pi").at("rmse").mean, 0.002, 1e-15);
  EXPECT_NEAR(m.stats.at("pi").at("rmse").spread, std::sqrt(2.0) * 0.001, 1e-15);
  EXPECT_EQ(m.stats.at("pi").at("rmse").n, 2);
  RegressResult r = Compare(s.suite, b, m);
  EXPECT_EQ(r.Count(Verdict::kNew), 1);        // hy switches: not in the baseline
  // pi rmse: +0.001 against 1e-4 tolerance + 3 * 0.00141 noise = 0.0044: inside the noise of these repeats.
  // pi switches (+0.5 < 2) and hy rmse are unchanged too.
  EXPECT_EQ(r.Count(Verdict::kUnchanged), 3);
  EXPECT_EQ(r.Count(Verdict::kRegressed), 0);
  EXPECT_FALSE(r.regressed());
  // Tighter repeats: the same mean change is a regression.
  runs[0].metrics["rmse"] = 0.00199;
  runs[1].metrics["rmse"] = 0.00201;
  r = Compare(s.suite, b, Summarise(runs));
  ASSERT_EQ(r.Count(Verdict::kRegressed), 1);
  const std::string xml = JUnitXml(r);
  EXPECT_NE(xml.find("<testcase classname=\"t.pi\" name=\"rmse\">"), std::string::npos) << xml;
  EXPECT_NE(xml.find("<failure type=\"regression\" message=\"rmse regressed: baseline 0.001 -&gt; now 0.002"),
            std::string::npos)
      << xml;
  EXPECT_NE(xml.find("failures=\"1\""), std::string::npos);
  EXPECT_NE(xml.find("<testcase classname=\"t.hy\" name=\"switches\">"), std::string::npos);
}

TEST(CompareTest, FailedRunsFailTheirCaseOnce) {
  const LoadedSuite s = TwoMetricSuite();
  Baseline b;
  b.name = "main";
  b.cases["pi"]["rmse"] = {0.001, 0.0, 1};
  b.cases["hy"]["rmse"] = {0.006, 0.0, 1};
  std::vector<RunMetrics> runs = {{1, "pi", "pi", false, "interlock: current above 3 A", {}},
                                  {2, "hy", "hy", true, "", {{"rmse", 0.006}}}};
  RegressResult r = Compare(s.suite, b, Summarise(runs));
  EXPECT_TRUE(r.regressed());
  EXPECT_EQ(r.Count(Verdict::kRegressed), 0);
  ASSERT_EQ(r.failures.count("pi"), 1u);
  const std::string xml = JUnitXml(r);
  EXPECT_NE(xml.find("name=\"run\""), std::string::npos);
  EXPECT_NE(xml.find("interlock: current above 3 A"), std::string::npos);
  EXPECT_NE(ResultTable(r).find("FAILED"), std::string::npos);
}

TEST(CompareTest, ResultAndBaselineJsonRoundTrip) {
  const LoadedSuite s = TwoMetricSuite();
  Baseline b;
  b.name = "main";
  b.version = 3;
  b.cases["pi"]["rmse"] = {0.001, 1e-5, 3};
  auto back = BaselineFromJson(BaselineToJson(b));
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back->version, 3);
  EXPECT_DOUBLE_EQ(back->cases.at("pi").at("rmse").spread, 1e-5);
  Json bad = BaselineToJson(b);
  bad["cases"]["pi"]["rmse"]["spread"] = -1;
  auto refused = BaselineFromJson(bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("cases.pi.rmse.spread"), std::string::npos);

  std::vector<RunMetrics> runs = {{1, "pi", "pi", true, "", {{"rmse", 0.01}}}};
  RegressResult r = Compare(s.suite, b, Summarise(runs));
  r.id = 5;
  auto rr = ResultFromJson(ResultToJson(r));
  ASSERT_TRUE(rr.ok()) << rr.status().ToString();
  EXPECT_EQ(rr->id, 5);
  ASSERT_EQ(rr->findings.size(), r.findings.size());
  EXPECT_EQ(rr->findings[0].verdict, r.findings[0].verdict);
  EXPECT_EQ(ResultTable(*rr), ResultTable(r));
}

// A baseline made from a batch ("benchctl baseline set --batch") is that batch's summary, read back through its
// JSON as the nights read it; the same batch number on another server (other runs, or the same cases measured
// again) is not, and the first difference is named. The night's cause then does not take that batch's specs for
// the baseline's code (server/nights.cc BaselineCodeOf).
TEST(CompareTest, ABaselineIsTheSummaryOfItsOwnBatchOnly) {
  const std::vector<RunMetrics> runs = {
      {1, "pi repeat:0", "pi", true, "", {{"rmse", 0.0010}, {"switches", 100}}},
      {2, "pi repeat:1", "pi", true, "", {{"rmse", 0.0013}, {"switches", 101}}},
      {3, "hy", "hy", true, "", {{"rmse", 0.006}, {"switches", 7}}},
  };
  Baseline b;
  b.name = "lab";
  b.source = "server lab-a:50051 batch 12";
  b.cases = Summarise(runs).stats;
  auto read = BaselineFromJson(Json::parse(BaselineToJson(b).dump()));
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(BaselineNotOfRuns(*read, runs), "");
  // Runs the baseline did not summarise: a repeat more, a value measured again, a case it lacks.
  auto more = runs;
  more.push_back({4, "pi repeat:2", "pi", true, "", {{"rmse", 0.0010}, {"switches", 100}}});
  EXPECT_EQ(BaselineNotOfRuns(*read, more).rfind("case pi, metric rmse: the baseline holds 0.00115 over 2 runs, "
                                                 "the runs give 0.0011 over 3", 0), 0u)
      << BaselineNotOfRuns(*read, more);
  auto again = runs;
  again[2].metrics["switches"] = 8;
  EXPECT_EQ(BaselineNotOfRuns(*read, again), "case hy, metric switches: the baseline holds 7 over 1 runs, the runs "
                                            "give 8 over 1");
  EXPECT_EQ(BaselineNotOfRuns(*read, {runs[0], runs[1]}), "case hy: not among the runs");
  auto fewer = runs;
  fewer[2].metrics.erase("switches");
  EXPECT_EQ(BaselineNotOfRuns(*read, fewer), "case hy, metric switches: not measured by the runs");
  // The runs' own metrics beyond the baseline's (a metric added since) do not matter.
  auto added = runs;
  for (auto& r : added) r.metrics["effort_V2s"] = 1.0;
  EXPECT_EQ(BaselineNotOfRuns(*read, added), "");
  EXPECT_EQ(BaselineNotOfRuns(Baseline{}, runs), "the baseline holds no case");
}

TEST(JUnitTest, EscapesNames) {
  RegressResult r;
  r.suite = "s<&>";
  Finding f;
  f.case_name = "a\"b";
  f.metric = "rmse";
  f.verdict = Verdict::kRegressed;
  f.message = "x < y & z";
  r.findings.push_back(f);
  const std::string xml = JUnitXml(r);
  EXPECT_NE(xml.find("s&lt;&amp;&gt;.a&quot;b"), std::string::npos) << xml;
  EXPECT_NE(xml.find("x &lt; y &amp; z"), std::string::npos);
  EXPECT_EQ(xml.find("x < y"), std::string::npos);
}

// A night per testcase: a regressed night fails with its cause first, an error night is an <error>, a passed
// night carries its summary and valve changes as output; counts match; names escaped.
TEST(JUnitTest, NightsWithTheirCause) {
  NightOutcome valve;
  valve.date = "2026-11-28", valve.verdict = "regressed", valve.suite = "ci", valve.baseline = "ci v1";
  valve.summary = "1 regressed, 14 unchanged; first: rmse < baseline";
  valve.cause = "valve", valve.cause_reason = "tonight's valve reproduces it";
  valve.batch_id = 12;
  valve.regressed_cases = {"map/duty=0.3"};
  valve.valve_changes = {"emu-a: R up +15.0 % since 2026-11-27, flagged 2026-11-28"};
  NightOutcome passed;
  passed.date = "2026-11-27", passed.verdict = "passed", passed.suite = "ci", passed.summary = "15 unchanged";
  passed.valve_changes = {"emu-b: L0 down -6.0 % since 2026-11-25, flagged 2026-11-27"};
  NightOutcome error;
  error.date = "2026-11-26", error.verdict = "error", error.suite = "ci", error.summary = "nights.suite_file: gone";
  const std::string xml = NightsJUnitXml({valve, passed, error});
  EXPECT_NE(xml.find(R"(<testsuites name="valvebench nights" tests="3" failures="1" errors="1">)"), std::string::npos) << xml;
  EXPECT_NE(xml.find(R"(<testcase classname="nights.ci" name="2026-11-28">)"), std::string::npos) << xml;
  EXPECT_NE(xml.find(R"(<failure type="regression" message="cause: valve (tonight&apos;s valve reproduces it); 1 regressed)"),
            std::string::npos) << xml;
  EXPECT_NE(xml.find("valve changed: emu-a: R up +15.0 % since 2026-11-27"), std::string::npos) << xml;
  EXPECT_NE(xml.find("regressed cases: map/duty=0.3"), std::string::npos) << xml;
  EXPECT_NE(xml.find("first: rmse &lt; baseline"), std::string::npos) << xml;
  EXPECT_EQ(xml.find("rmse < baseline"), std::string::npos) << xml;
  EXPECT_NE(xml.find(R"(<error type="night-error" message="nights.suite_file: gone">)"), std::string::npos) << xml;
  const auto out = xml.find("<system-out>");
  ASSERT_NE(out, std::string::npos) << xml;
  EXPECT_NE(xml.find("valve changed: emu-b: L0 down", out), std::string::npos) << xml;
}

// ---- cron ----

CivilMinute At(int y, int mo, int d, int h, int mi) { return {y, mo, d, h, mi}; }

CivilMinute NextOf(const std::string& expr, CivilMinute after) {
  auto c = Cron::Parse(expr);
  EXPECT_TRUE(c.ok()) << c.status().ToString();
  auto n = c->Next(after);
  EXPECT_TRUE(n.ok()) << n.status().ToString();
  return n.ok() ? *n : CivilMinute{};
}

TEST(CronTest, NextFire) {
  EXPECT_EQ(NextOf("0 2 * * *", At(2026, 11, 21, 9, 13)), At(2026, 11, 22, 2, 0));
  EXPECT_EQ(NextOf("0 2 * * *", At(2026, 11, 21, 1, 59)), At(2026, 11, 21, 2, 0));
  EXPECT_EQ(NextOf("0 2 * * *", At(2026, 11, 21, 2, 0)), At(2026, 11, 22, 2, 0));  // strictly after
  EXPECT_EQ(NextOf("*/15 * * * *", At(2026, 11, 21, 9, 13)), At(2026, 11, 21, 9, 15));
  EXPECT_EQ(NextOf("*/15 * * * *", At(2026, 11, 21, 23, 45)), At(2026, 11, 22, 0, 0));
  EXPECT_EQ(NextOf("30 3 * * 1-5", At(2026, 11, 21, 9, 0)), At(2026, 11, 23, 3, 30));  // Sat -> Mon
  EXPECT_EQ(NextOf("0 0 1 jan *", At(2026, 11, 21, 9, 0)), At(2027, 1, 1, 0, 0));
  EXPECT_EQ(NextOf("0 12 29 2 *", At(2026, 3, 1, 0, 0)), At(2028, 2, 29, 12, 0));      // next leap day
  EXPECT_EQ(NextOf("0 0 * * 7", At(2026, 11, 21, 0, 0)), At(2026, 11, 22, 0, 0));      // 7 = Sunday
  EXPECT_EQ(NextOf("0 0 * * SUN", At(2026, 11, 21, 0, 0)), At(2026, 11, 22, 0, 0));
  // Both day fields restricted: either matches (Vixie cron). 2026-11-25 is a Wednesday; the 1st comes later.
  EXPECT_EQ(NextOf("0 6 1 * WED", At(2026, 11, 21, 0, 0)), At(2026, 11, 25, 6, 0));
  EXPECT_EQ(NextOf("5,35 1-2 * * *", At(2026, 11, 21, 1, 35)), At(2026, 11, 21, 2, 5));
  EXPECT_EQ(NextOf("0 22 31 12 *", At(2026, 12, 31, 22, 0)), At(2027, 12, 31, 22, 0));  // year rollover
  EXPECT_EQ(DayOfWeek(2026, 11, 21), 6);  // Saturday
}

TEST(CronTest, BadExpressionsNameTheField) {
  struct Case {
    const char* expr;
    const char* needle;
  } cases[] = {{"0 2 * *", "expected 5 fields"},
               {"60 * * * *", "minute: 60 is outside 0-59"},
               {"0 24 * * *", "hour: 24 is outside 0-23"},
               {"0 0 0 * *", "day-of-month: 0 is outside 1-31"},
               {"0 0 * 13 *", "month: 13 is outside 1-12"},
               {"0 0 * * 8", "day-of-week: 8 is outside 0-6"},
               {"*/0 * * * *", "minute: step '0'"},
               {"5-1 * * * *", "minute: range '5-1' runs backwards"},
               {"x * * * *", "minute: 'x' is not a number"},
               {"0 0 * FOO *", "month: 'FOO'"}};
  for (const auto& c : cases) {
    auto p = Cron::Parse(c.expr);
    ASSERT_FALSE(p.ok()) << c.expr;
    EXPECT_NE(p.status().message().find(c.needle), std::string::npos) << c.expr << ": " << p.status().message();
  }
  auto never = Cron::Parse("0 0 31 2 *");
  ASSERT_TRUE(never.ok());
  EXPECT_EQ(never->Next(At(2026, 1, 1, 0, 0)).status().code(), StatusCode::kNotFound);
}

TEST(CronTest, UnixWrappersInUtc) {
  auto c = Cron::Parse("0 2 * * *");
  ASSERT_TRUE(c.ok());
  const double t = 1795252380.0;  // 2026-11-21 09:13:00 UTC
  auto n = c->NextUnix(t, true);
  ASSERT_TRUE(n.ok());
  EXPECT_DOUBLE_EQ(*n, 1795312800.0);  // 2026-11-22 02:00:00 UTC
  EXPECT_EQ(DateOf(*n, true), "2026-11-22");
}

}  // namespace
}  // namespace vb::regress
