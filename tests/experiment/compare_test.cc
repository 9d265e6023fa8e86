#include <fmt/format.h>
#include <gtest/gtest.h>

#include "experiment/compare.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "common/run_key.h"
#include "valvebench/v1/api.pb.h"

namespace vb::experiment {
namespace {

RunRecord R(const std::string& name, double rmse, double effort, bool ok = true) {
  RunRecord r;
  r.key = NamedRun(name);
  r.controller = name;
  r.ok = ok;
  r.metrics["rmse"] = rmse;
  r.metrics["effort_l2"] = effort;
  return r;
}

const CompareRow& Row(const Comparison& c, const std::string& name) {
  for (const auto& r : c.rows)
    if (r.name == name) return r;
  ADD_FAILURE() << "no row " << name;
  return c.rows.front();
}

TEST(Compare, RanksByRmseAndMarksTheParetoFront) {
  const Comparison c = Compare({R("a", 3.0, 1.0), R("b", 1.0, 3.0), R("c", 2.0, 2.0), R("d", 2.5, 2.5)});
  ASSERT_EQ(c.rows.size(), 4u);
  EXPECT_EQ(c.rows[0].name, "b");
  EXPECT_EQ(Row(c, "b").rank, 1);
  EXPECT_EQ(Row(c, "c").rank, 2);
  EXPECT_EQ(Row(c, "d").rank, 3);
  EXPECT_EQ(Row(c, "a").rank, 4);
  EXPECT_TRUE(Row(c, "a").pareto);
  EXPECT_TRUE(Row(c, "b").pareto);
  EXPECT_TRUE(Row(c, "c").pareto);
  EXPECT_FALSE(Row(c, "d").pareto) << "d is dominated by c";
}

TEST(Compare, DifferencesInsideTheRepeatSpreadAreNotRanked) {
  // x: 1.0 +/- ~0.14, y: 1.1 +/- ~0.14 -> same rank; z: 2.0 -> next rank.
  const Comparison c = Compare({R("x", 0.9, 1), R("x", 1.1, 1), R("x", 1.0, 1), R("y", 1.0, 1), R("y", 1.2, 1),
                                R("y", 1.1, 1), R("z", 2.0, 1), R("z", 2.0, 1)});
  EXPECT_EQ(Row(c, "x").runs, 3);
  EXPECT_NEAR(Row(c, "x").metrics.at("rmse").mean, 1.0, 1e-12);
  EXPECT_NEAR(Row(c, "x").metrics.at("rmse").spread, 0.1, 1e-12);
  EXPECT_EQ(Row(c, "x").rank, 1);
  EXPECT_EQ(Row(c, "y").rank, 1);
  EXPECT_EQ(Row(c, "z").rank, 2);
}

TEST(Compare, FailedRunsAreCountedNotAveraged) {
  const Comparison c = Compare({R("a", 1.0, 1.0), R("a", 99.0, 99.0, false)});
  EXPECT_EQ(Row(c, "a").failed, 1);
  EXPECT_NEAR(Row(c, "a").metrics.at("rmse").mean, 1.0, 1e-12);
  EXPECT_NE(ComparisonCsv(c).find("rank,name,controller"), std::string::npos);
  EXPECT_NE(ComparisonTable(c).find("Pareto"), std::string::npos);
}

TEST(Compare, CsvQuotesNamesSoCommasAndQuotesStayInTheirColumn) {
  const Comparison c = Compare({R("say \"hi\", then go", 1.0, 1.0)});
  const std::string csv = ComparisonCsv(c);
  EXPECT_NE(csv.find(",\"say \"\"hi\"\", then go\","), std::string::npos) << csv;
}


size_t Widest(const std::string& text) {
  size_t w = 0;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    size_t n = 0;
    for (unsigned char ch : line) n += (ch & 0xC0) != 0x80;  // characters, not bytes
    w = std::max(w, n);
  }
  return w;
}

// Seed 001's four laws as the emulator measures them (docs/comparison.md), with every metric a run records.
std::vector<RunRecord> CurrentLaws() {
  struct L {
    const char* law;
    double rmse, rate, sw_loss, diode;
  };
  std::vector<RunRecord> out;
  for (const L& l : {L{"hysteresis_current", 0.006018, 3437, 0.0021, 0.2561}, L{"pi_current", 0.000953, 40000, 0.0247, 0.2553},
                     L{"predictive_current", 0.000694, 40000, 0.0247, 0.2550}, L{"fuzzy_current", 0.000538, 40000, 0.0247, 0.2551}}) {
    RunRecord r;
    r.key = NamedRun("compare-current-controllers/" + std::string(l.law).substr(0, std::string(l.law).find('_')));
    r.controller = l.law;
    r.metrics = {{"rmse", l.rmse}, {"iae", l.rmse * 0.08}, {"max_abs_error", l.rmse * 3}, {"overshoot", NAN},
                 {"settling_time_s", NAN}, {"effort_l2", 3.67}, {"effort_rms", 12.97}, {"energy_J", 0.26},
                 {"switches", l.rate * 0.08}, {"mean_current_A", 0.5}, {"opening_delay_s", NAN},
                 {"closing_delay_s", NAN}, {"mean_position_m", 3e-4}, {"mean_position_pct", 100},
                 {"mean_flow_kg_per_s", 1e-3}, {"switching_rate_Hz", l.rate}, {"diode_loss_W", l.diode},
                 {"switching_loss_W", l.sw_loss}, {"driver_loss_W", l.diode + l.sw_loss}, {"effort_u_l2", NAN},
                 {"pwm_frequency_Hz", NAN}, {"pwm_duty", NAN}, {"ripple_pp_A", NAN}, {"ripple_mid_A", NAN}};
    out.push_back(r);
  }
  return out;
}

TEST(CompareTable, CurrentLawsFitIn120ColumnsWithUnitsAndWithoutTheSharedPrefix) {
  const Comparison c = Compare(CurrentLaws());
  const std::string t = ComparisonTable(c);
  EXPECT_LE(Widest(t), 120u) << t;
  EXPECT_NE(t.find("RMSE [mA]"), std::string::npos) << t;
  EXPECT_NE(t.find("sw rate [kHz]"), std::string::npos) << t;
  EXPECT_NE(t.find("driver loss [mW]"), std::string::npos) << t;
  EXPECT_NE(t.find("0.538"), std::string::npos) << "0.000538 A in mA: " << t;
  EXPECT_NE(t.find("40.00"), std::string::npos) << "40000 Hz in kHz: " << t;
  // Metrics that apply to no row (a hold has no overshoot, settling or opening delay) are absent, not 0.
  EXPECT_EQ(t.find("overshoot"), std::string::npos) << t;
  EXPECT_EQ(t.find("settling"), std::string::npos) << t;
  EXPECT_EQ(t.find("open delay"), std::string::npos) << t;
  // The 28-character prefix is said once, not on every row.
  EXPECT_EQ(t.find("compare-current-controllers/"), std::string::npos) << t;
  EXPECT_EQ(t.rfind("compare-current-controllers: 4 cases", 0), 0u) << t;
}

// The web page formats its cells from MetricColumnDisplay: the same header, scale and decimals as the text table.
TEST(CompareTable, ColumnDisplayIsTheTextTablesChoice) {
  const Comparison c = Compare(CurrentLaws());
  const ColumnDisplay rmse = MetricColumnDisplay(c, "rmse");
  EXPECT_EQ(rmse.header, "RMSE [mA]");
  EXPECT_EQ(rmse.unit, "mA");
  EXPECT_DOUBLE_EQ(rmse.scale, 1e3);
  const ColumnDisplay rate = MetricColumnDisplay(c, "switching_rate_Hz");
  EXPECT_EQ(rate.header, "sw rate [kHz]");
  EXPECT_DOUBLE_EQ(rate.scale, 1e-3);
  EXPECT_EQ(rate.decimals, 2);  // "40.00", as the table prints it
  const std::string t = ComparisonTable(c);
  const double fuzzy = Row(c, "compare-current-controllers/fuzzy").metrics.at("rmse").mean;
  EXPECT_NE(t.find(fmt::format("{:.{}f}", fuzzy * rmse.scale, rmse.decimals)), std::string::npos) << t;
  const auto defaults = DefaultMetricColumns(c);
  EXPECT_EQ(defaults.front(), "rmse");
  EXPECT_NE(std::find(defaults.begin(), defaults.end(), "driver_loss_W"), defaults.end());
  EXPECT_EQ(std::find(defaults.begin(), defaults.end(), "overshoot"), defaults.end()) << "applies to no row";
  // A sweep axis: duty in %, a pressure in kPa.
  EXPECT_EQ(SweepColumnDisplay("controller.open_loop_pwm.segments[0].duty", {0.0, 0.5, 1.0}).header, "duty [%]");
  const ColumnDisplay p = SweepColumnDisplay("conditions.supply_pressure_Pa", {0.0, 2e5, 6e5});
  EXPECT_EQ(p.unit, "kPa");
  EXPECT_DOUBLE_EQ(p.scale, 1e-3);
  // The prefix table, largest first, with the base unit in it.
  const auto prefixes = SiPrefixes();
  ASSERT_GE(prefixes.size(), 5u);
  EXPECT_EQ(prefixes.front().symbol, "G");
  for (size_t k = 1; k < prefixes.size(); ++k) EXPECT_GT(prefixes[k].scale, prefixes[k - 1].scale);
  EXPECT_NE(std::find_if(prefixes.begin(), prefixes.end(), [](const SiPrefix& x) { return x.symbol == "µ"; }),
            prefixes.end());
}

TEST(CompareTable, CurrentLawsTradeRmseAgainstTheDriverLoss) {
  const Comparison c = Compare(CurrentLaws());
  EXPECT_EQ(c.effort_metric, "driver_loss_W");
  EXPECT_TRUE(Row(c, "compare-current-controllers/fuzzy").pareto) << "best RMSE";
  EXPECT_TRUE(Row(c, "compare-current-controllers/hysteresis").pareto) << "12x fewer edges: least loss";
  EXPECT_FALSE(Row(c, "compare-current-controllers/pi").pareto);
  EXPECT_NE(ComparisonTable(c).find("Pareto-optimal in (RMSE, driver loss)"), std::string::npos);
}

TEST(CompareTable, MetricsAndWidePickTheColumnsInAStableOrder) {
  const Comparison c = Compare(CurrentLaws());
  const std::string picked = ComparisonTable(c, {{"switches", "rmse"}, false});
  const size_t sw = picked.find("switches"), rmse = picked.find("RMSE [mA]");
  ASSERT_NE(sw, std::string::npos) << picked;
  ASSERT_NE(rmse, std::string::npos) << picked;
  EXPECT_LT(sw, rmse) << "the asked order";
  EXPECT_EQ(picked.substr(0, picked.find("\n", picked.find("\n") + 1)).find("driver loss"), std::string::npos)
      << "only the asked columns: " << picked;
  const std::string wide = ComparisonTable(c, {{}, true});
  EXPECT_NE(wide.find("||v||2 [V s^0.5]"), std::string::npos) << wide;
  EXPECT_NE(wide.find("energy [mJ]"), std::string::npos) << wide;
  EXPECT_EQ(wide.find("overshoot"), std::string::npos) << "still absent: it applies to no row";
  EXPECT_EQ(CheckTableOptions(c, {{"rmse"}, false}), "");
  EXPECT_NE(CheckTableOptions(c, {{"rmse", "speed"}, false}).find("no metric speed"), std::string::npos);
  // Columns follow MetricList's order whatever order the runs' maps come in.
  EXPECT_EQ(c.columns.front(), "rmse");
  EXPECT_EQ(Compare(CurrentLaws()).columns, c.columns);
  EXPECT_EQ(ComparisonTable(Compare(CurrentLaws())), ComparisonTable(c));
}

TEST(CompareTable, PositionLawsUseTheirForceNormAsEffort) {
  std::vector<RunRecord> runs;
  for (auto [law, rmse, u] : {std::tuple{"cascade_pi_position", 6.46e-5, 0.21}, std::tuple{"sliding_mode_position", 6.40e-5, 0.12}}) {
    RunRecord r;
    r.key = NamedRun(std::string("position/") + law);
    r.controller = law;
    r.metrics = {{"rmse", rmse}, {"overshoot", 0.2}, {"max_abs_error", NAN}, {"effort_u_l2", u}, {"effort_l2", 152.5}};
    runs.push_back(r);
  }
  const Comparison c = Compare(runs);
  EXPECT_EQ(c.effort_metric, "effort_u_l2");
  const std::string t = ComparisonTable(c);
  EXPECT_NE(t.find("RMSE [µm]"), std::string::npos) << t;
  EXPECT_NE(t.find("||u||2 [mN s^0.5]"), std::string::npos) << t;
  EXPECT_NE(t.find("overshoot [%]"), std::string::npos) << t;
  EXPECT_EQ(t.find("max|e|"), std::string::npos) << t;
}

TEST(CompareTable, StaticMapIsPositionAgainstDutyOneColumnPerPressure) {
  std::vector<RunRecord> runs;
  for (const char* variant : {"fig8", "fig9"})
    for (double other : {200000.0, 400000.0})
      for (double duty : {0.0, 0.5, 1.0}) {
        const bool f8 = std::string(variant) == "fig8";
        RunKey key{std::string("static-map/") + variant,
                   {{"controller.open_loop_pwm.segments[0].duty", duty},
                    {f8 ? "conditions.supply_pressure_Pa" : "controller.open_loop_pwm.segments[0].frequency_Hz",
                     f8 ? other : other / 4000}},
                   -1};
        RunRecord r;
        r.key = key;
        r.controller = "open_loop_pwm";
        r.metrics = {{"mean_position_pct", 100 * duty * (f8 ? other / 400000 : 1)}, {"mean_current_A", duty}};
        runs.push_back(r);
      }
  const Comparison c = Compare(runs);
  const std::string t = ComparisonTable(c);
  EXPECT_NE(t.find("fig8: mean position [% of stroke] against duty, one column per supply_pressure"), std::string::npos) << t;
  EXPECT_NE(t.find("fig9: mean position"), std::string::npos) << "the second variant is kept: " << t;
  EXPECT_NE(t.find("200 kPa"), std::string::npos) << t;
  EXPECT_NE(t.find("100 Hz"), std::string::npos) << t;
  EXPECT_NE(t.find("50.0"), std::string::npos) << "fig8 at 200 kPa, duty 100 %: " << t;
  EXPECT_LE(Widest(t), 120u) << t;
  // --wide: one row per run with the sweep values as columns; CSV and JSON carry them too.
  const std::string wide = ComparisonTable(c, {{}, true});
  EXPECT_NE(wide.find("supply_pressure [kPa]"), std::string::npos) << wide;
  EXPECT_NE(wide.find("mean x [%]"), std::string::npos) << wide;
  const std::string csv = ComparisonCsv(c);
  EXPECT_NE(csv.find("\"controller.open_loop_pwm.segments[0].duty\",\"conditions.supply_pressure_Pa\""), std::string::npos) << csv;
  EXPECT_NE(csv.find("mean_position_pct"), std::string::npos);
  EXPECT_NE(ComparisonJson(c).find("\"conditions.supply_pressure_Pa\": 200000"), std::string::npos);
}

TEST(CompareTable, DitherShowsSeed003TableIBesidePlannedAndAchieved) {
  std::vector<RunRecord> runs;
  for (auto [avg, f, d] : {std::tuple{0.1, 149.3594, 0.116566}, std::tuple{0.3, 332.997, 0.355880}}) {
    RunKey key{"dither", {{"controller.dither_pwm.average_current_A", avg}}, -1};
    RunRecord r;
    r.key = key;
    r.controller = "dither_pwm";
    r.metrics = {{"pwm_frequency_Hz", f}, {"pwm_duty", d}, {"ripple_pp_A", 0.0500}, {"ripple_mid_A", avg}};
    runs.push_back(r);
  }
  const std::string t = ComparisonTable(Compare(runs));
  EXPECT_NE(t.find("f plan [Hz]"), std::string::npos) << t;
  EXPECT_EQ(t.rfind("dither: 2 cases", 0), 0u) << t;
  EXPECT_NE(t.find("Table I f [Hz]"), std::string::npos) << t;
  EXPECT_NE(t.find("149.36"), std::string::npos) << "the paper's 0.1 A row: " << t;
  EXPECT_NE(t.find("333.99"), std::string::npos) << "the paper's 0.3 A row as printed: " << t;
  EXPECT_NE(t.find("333.00"), std::string::npos) << "ours, beside the paper's typo: " << t;
  EXPECT_NE(t.find("Table I I_amp [mA]"), std::string::npos) << t;
  EXPECT_NE(t.find("I_amp p-p [mA]"), std::string::npos) << t;
  EXPECT_EQ(t.find("open_loop_pwm"), std::string::npos) << t;
  EXPECT_LE(Widest(t), 120u) << t;
}

TEST(CompareTable, SiUnitsFollowTheLaw) {
  EXPECT_EQ(SiUnit("rmse", "pi_current"), "A");
  EXPECT_EQ(SiUnit("rmse", "sliding_mode_position"), "m");
  EXPECT_EQ(SiUnit("iae", "sliding_mode_position"), "m s");
  EXPECT_EQ(SiUnit("effort_l2", "pi_current"), "V s^0.5");
  EXPECT_EQ(SiUnit("effort_u_l2", "cascade_pi_position"), "N s^0.5");
  EXPECT_EQ(SiUnit("overshoot", "pi_current"), "1");
  EXPECT_EQ(SiUnit("pwm_duty", "dither_pwm"), "1");
  EXPECT_EQ(SiUnit("mean_position_pct", "open_loop_pwm"), "%");
  EXPECT_EQ(SiUnit("mean_flow_kg_per_s", "open_loop_pwm"), "kg/s");
  EXPECT_EQ(SiUnit("driver_loss_W", "pi_current"), "W");
  EXPECT_EQ(SiUnit("switches", "pi_current"), "1");
}

TEST(Compare, RowsCarryTheirKeyAndRunIdsNotTextToParseBack) {
  // Two repeats of one sweep point, one other point, and a plain run whose name merely looks like a sweep.
  const RunKey a0{"m/fig8", {{"controller.open_loop_pwm.segments[0].duty", 0.35}, {"conditions.supply_V", 24}}, 0};
  RunKey a1 = a0;
  a1.repeat = 1;
  RunKey b = a0;
  b.sweep[0].value = 0.5;
  b.repeat = -1;
  std::vector<RunRecord> runs;
  std::int64_t id = 10;
  for (const RunKey& k : {a0, b, a1, NamedRun("odd sweep:x=1")}) {
    RunRecord r;
    r.key = k;
    r.run_id = id++;
    r.controller = "open_loop_pwm";
    r.metrics = {{"mean_position_pct", 50}};
    runs.push_back(r);
  }
  const Comparison c = Compare(runs);
  ASSERT_EQ(c.rows.size(), 3u);
  RunKey case_a = a0;
  case_a.repeat = -1;
  EXPECT_EQ(c.rows[0].key, case_a) << "repeats share the case's key, repeat -1";
  EXPECT_EQ(c.rows[0].run_ids, (std::vector<std::int64_t>{10, 12}));
  EXPECT_EQ(c.rows[0].runs, 2);
  EXPECT_EQ(c.rows[1].key, b);
  EXPECT_EQ(c.rows[1].run_ids, (std::vector<std::int64_t>{11}));
  EXPECT_EQ(c.rows[2].key, NamedRun("odd sweep:x=1")) << "a name is never parsed for sweep coordinates";
  EXPECT_EQ(c.rows[2].run_ids, (std::vector<std::int64_t>{13}));
  // The renderers read the coordinates from the key: CSV columns, JSON's sweep and key.
  const std::string csv = ComparisonCsv(c);
  EXPECT_NE(csv.find("\"conditions.supply_V\""), std::string::npos) << csv;
  EXPECT_EQ(csv.find(",x,"), std::string::npos) << "no axis made up from a name: " << csv;
  const std::string json = ComparisonJson(c);
  EXPECT_NE(json.find("\"run_ids\": [\n        10,\n        12\n      ]"), std::string::npos) << json;
  EXPECT_NE(json.find("\"field\": \"controller.open_loop_pwm.segments[0].duty\""), std::string::npos) << json;
  const std::string wide = ComparisonTable(c, {{}, true});
  EXPECT_NE(wide.find("supply [V]"), std::string::npos) << "a sweep column from the key: " << wide;
}

// The service's comparison becomes the Comparison the CLI's and the web's files are written from; a metric a
// row lacks is an empty CSV field and a JSON null there (docs/cli.md "Missing values").
TEST(CompareFiles, FromTheServiceAMissingMetricIsAnEmptyFieldAndANull) {
  valvebench::v1::CompareRunsResponse p;
  p.set_rank_metric("rmse");
  p.set_effort_metric("effort_l2");
  p.add_columns("rmse");
  p.add_columns("effort_l2");
  auto* a = p.add_rows();
  a->set_name("c/pi");
  a->set_controller("pi_current");
  a->set_runs(1);
  a->set_rank(1);
  (*a->mutable_metrics())["rmse"].set_mean(0.001);
  (*a->mutable_metrics())["rmse"].set_n(1);
  auto* b = p.add_rows();
  b->set_name("c/smc");
  b->set_controller("sliding_mode_current");
  b->set_runs(1);
  b->set_failed(1);
  const Comparison c = ComparisonFromProto(p);
  ASSERT_EQ(c.rows.size(), 2u);
  EXPECT_EQ(c.rows[0].metrics.at("rmse").n, 1);
  const std::string csv = ComparisonCsv(c);
  EXPECT_NE(csv.find("\"c/pi\",pi_current,1,0,0,0.001,0,,"), std::string::npos) << csv;
  EXPECT_NE(csv.find("\"c/smc\",sliding_mode_current,1,1,0,,,,"), std::string::npos) << csv;
  EXPECT_EQ(csv.find("nan"), std::string::npos) << csv;
  const std::string json = ComparisonJson(c);
  EXPECT_NE(json.find("\"effort_l2\": null"), std::string::npos) << json;
  EXPECT_EQ(json.find("NaN"), std::string::npos) << json;
}

}  // namespace
}  // namespace vb::experiment

// Issue 28: a list of runs shows each run's headline metrics as its law's comparison does: the effort axis of
// the Compare page (driver loss for current laws, ||u||2 for position laws), never one effort for all.
TEST(CompareTable, HeadlineMetricsAreTheComparisonsOwn) {
  const auto current = vb::experiment::EffortMetricOf("pi_current");
  EXPECT_EQ(current.metric, "driver_loss_W");
  EXPECT_EQ(current.label, "driver loss");
  EXPECT_EQ(current.unit, "W");
  EXPECT_EQ(vb::experiment::EffortMetricOf("sliding_mode_position").metric, "effort_u_l2");
  EXPECT_EQ(vb::experiment::EffortMetricOf("open_loop_pwm").metric, "effort_l2");
  EXPECT_EQ(vb::experiment::RankMetricOf("pi_current").unit, "A");
  EXPECT_EQ(vb::experiment::RankMetricOf("cascade_pi_position").unit, "m");
  EXPECT_EQ(vb::experiment::RankMetricOf("cascade_pi_position").label, "RMSE");
}
