// The bench twin on the server (issue 38, docs/track.md "On the server"): a bench's "health" block queues a
// switch-on check before each night's suite, an emulated bench's "drift" changes its valve night by night, the
// server identifies and tracks each bench's checks night by night and says why a night regressed (the valve or
// the code), and `benchctl health` tracks each bench's checks from the server's store. The config's blocks are validated with
// errors naming the field.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <nlohmann/json.hpp>
#include <set>
#include <thread>

#include "../common/run_command.h"
#include "client/client.h"
#include "db/sqlite_store.h"
#include "model/params.h"
#include "runs/bench_setup.h"
#include "runs/query.h"
#include "server/config.h"
#include "server/bench_twin.h"
#include "server/health_check.h"
#include "service/bench_health.h"
#include "server_process.h"

namespace vb {
namespace {

const std::string kSuites = std::string(VB_SOURCE_DIR) + "/examples/suites/";

std::string ConfigError(const valvebench::v1::ServerConfig& c) {
  auto s = server::SettingsFromConfig(c, "");
  return s.ok() ? std::string() : s.status().message();
}

TEST(HealthConfig, ValidatesAndNamesTheField) {
  auto c = testing::MinimalConfig();
  auto* h = c.mutable_benches(0)->mutable_health();
  EXPECT_NE(ConfigError(c).find("benches[0].health.supply_V: give at least one"), std::string::npos) << ConfigError(c);
  h->add_supply_v(24.0);
  EXPECT_NE(ConfigError(c).find("benches[0].health.supply_pressure_Pa"), std::string::npos) << ConfigError(c);
  h->add_supply_pressure_pa(-1.0);
  EXPECT_NE(ConfigError(c).find("benches[0].health.supply_pressure_Pa[0]"), std::string::npos) << ConfigError(c);
  h->set_supply_pressure_pa(0, 2e5);
  EXPECT_EQ(ConfigError(c), "");
  h->add_supply_v(5000.0);  // above the bench's max_supply_V (1000 V for an emulated bench)
  EXPECT_NE(ConfigError(c).find("benches[0].health.supply_V[1]"), std::string::npos) << ConfigError(c);
  h->mutable_supply_v()->RemoveLast();
  h->set_duration_s(1e-4);
  EXPECT_NE(ConfigError(c).find("benches[0].health.duration_s"), std::string::npos) << ConfigError(c);
  h->set_duration_s(0.0);
  h->set_record_rate_hz(10.0);
  EXPECT_NE(ConfigError(c).find("benches[0].health.record_rate_Hz"), std::string::npos) << ConfigError(c);
  h->set_record_rate_hz(0.0);

  auto* d = c.mutable_benches(0)->add_drift();
  d->set_parameter("R_ohm");
  d->set_step(0.04);
  d->set_from_night(3);
  EXPECT_NE(ConfigError(c).find("benches[0].drift[0].parameter: 'R_ohm' is not a model parameter"), std::string::npos)
      << ConfigError(c);
  d->set_parameter("R");
  EXPECT_EQ(ConfigError(c), "");
  d->set_from_night(0);
  EXPECT_NE(ConfigError(c).find("benches[0].drift[0].from_night"), std::string::npos) << ConfigError(c);
  d->set_from_night(3);
  d->set_step(0.0);
  EXPECT_NE(ConfigError(c).find("benches[0].drift[0]: give a step or a per_night"), std::string::npos)
      << ConfigError(c);
  d->set_step(0.04);
  // Dry friction growing in the guide: an effect the preset lacks, so it needs the value it starts from.
  auto* f = c.mutable_benches(0)->add_drift();
  f->set_parameter("coulomb_friction.F_x");
  f->set_per_night(0.5);
  f->set_from_night(3);
  EXPECT_NE(ConfigError(c).find("benches[0].drift[1].parameter: 'coulomb_friction.F_x'"), std::string::npos)
      << ConfigError(c);
  EXPECT_NE(ConfigError(c).find("unknown parameter of coulomb_friction (known: F_c, F_s)"), std::string::npos)
      << ConfigError(c);
  f->set_parameter("coulomb_friction.F_c");
  EXPECT_NE(ConfigError(c).find("benches[0].drift[1].base: coulomb_friction.F_c is 0 in the bench's model"),
            std::string::npos) << ConfigError(c);
  f->set_base(-0.3);
  EXPECT_NE(ConfigError(c).find("benches[0].drift[1].base: must be >= 0"), std::string::npos) << ConfigError(c);
  f->set_base(0.3);
  EXPECT_EQ(ConfigError(c), "");
  c.mutable_benches(0)->mutable_drift()->RemoveLast();
  c.mutable_benches(0)->set_current_noise_a(-1e-3);
  EXPECT_NE(ConfigError(c).find("benches[0].current_noise_A"), std::string::npos) << ConfigError(c);
  c.mutable_benches(0)->set_current_noise_a(1e-3);
  auto ok = server::SettingsFromConfig(c, "");
  ASSERT_TRUE(ok.ok()) << ok.status().message();
  ASSERT_EQ(ok->benches[0].drift.size(), 1u);
  EXPECT_EQ(ok->benches[0].drift[0].parameter, "R");
  EXPECT_EQ(ok->benches[0].current_noise_A, 1e-3);

  // A hardware valve drifts on its own: no drift block there.
  auto hw = testing::MinimalConfig();
  auto* b = hw.mutable_benches(0);
  b->clear_model();
  b->set_kind("hid");
  b->add_drift()->set_parameter("R");
  EXPECT_NE(ConfigError(hw).find("benches[0].drift/current_noise_A: only an emulated bench"), std::string::npos)
      << ConfigError(hw);
}

TEST(ValveDrift, AStepAndARampFromTheirNight) {
  runs::ValveDrift step{"R", 0.04, 0.0, 5};
  EXPECT_EQ(runs::DriftFactor(step, 0), 1.0);  // no night yet
  EXPECT_EQ(runs::DriftFactor(step, 4), 1.0);
  EXPECT_DOUBLE_EQ(runs::DriftFactor(step, 5), 1.04);
  EXPECT_DOUBLE_EQ(runs::DriftFactor(step, 60), 1.04);
  runs::ValveDrift ramp{"k", 0.0, -0.01, 10};
  EXPECT_EQ(runs::DriftFactor(ramp, 9), 1.0);
  EXPECT_DOUBLE_EQ(runs::DriftFactor(ramp, 10), 1.0);
  EXPECT_DOUBLE_EQ(runs::DriftFactor(ramp, 30), 0.8);

  // Applied to a plant: R relative to its own, dry friction from nothing (its base), F_s kept >= F_c.
  auto plant = model::Preset("taghizadeh2009");
  ASSERT_TRUE(plant.ok());
  const double R0 = plant->R_ohm;
  const std::vector<runs::ValveDrift> drift = {step, {"coulomb_friction.F_c", 0.0, 0.5, 3, 0.3}};
  model::PlantParams night2 = *plant, night5 = *plant;
  ASSERT_TRUE(runs::ApplyDrift(drift, 2, &night2).ok());
  EXPECT_EQ(night2.R_ohm, R0);
  EXPECT_EQ(night2.effects.friction_F_c_N, 0.0);
  ASSERT_TRUE(runs::ApplyDrift(drift, 5, &night5).ok());
  EXPECT_DOUBLE_EQ(night5.R_ohm, 1.04 * R0);
  EXPECT_DOUBLE_EQ(night5.effects.friction_F_c_N, 0.3 * 2.0);  // 0.3 N x (1 + 0.5 x 2)
  EXPECT_GE(night5.effects.friction_F_s_N, night5.effects.friction_F_c_N);
  model::PlantParams bad = *plant;
  EXPECT_FALSE(runs::ApplyDrift({{"coulomb_friction.F_c", 0.0, 1e6, 1, 1.0}}, 100, &bad).ok());

  valvebench::v1::ExperimentSpec spec;
  EXPECT_EQ(runs::NightNumberOf(spec), 0);
  spec.add_tags("night");
  spec.add_tags(runs::NightNumberTag(17));
  EXPECT_EQ(runs::NightNumberOf(spec), 17);
}

// The health check's runs: one per supply and pressure, from rest with one gate step, and one hold (the same
// switch-on, then PWM) at the first supply and the highest pressure; pinned to the bench, tagged with the night,
// queued ahead of the suite.
TEST(HealthCheck, OneSwitchOnRunPerSupplyAndPressureAndAHold) {
  auto c = testing::MinimalConfig();
  auto* h = c.mutable_benches(0)->mutable_health();
  h->add_supply_v(24.0), h->add_supply_v(20.0);
  h->add_supply_pressure_pa(1e5), h->add_supply_pressure_pa(4e5);
  auto s = server::SettingsFromConfig(c, "");
  ASSERT_TRUE(s.ok()) << s.status().message();
  auto specs = server::HealthCheckSpecs(s->benches[0], "2026-11-29", 12);
  ASSERT_EQ(specs.size(), 5u);
  const auto hold = specs.back();
  specs.pop_back();
  std::set<std::pair<double, double>> conditions;
  for (const auto& spec : specs) {
    conditions.insert({spec.conditions().supply_v(), spec.conditions().supply_pressure_pa()});
    EXPECT_EQ(spec.bench().name(), "emu");
    EXPECT_EQ(spec.bench().model().preset(), "taghizadeh2009");
    EXPECT_EQ(runs::NightNumberOf(spec), 12);
    const std::set<std::string> tags(spec.tags().begin(), spec.tags().end());
    EXPECT_TRUE(tags.count("health") && tags.count("health:emu") && tags.count("night:2026-11-29")) << spec.DebugString();
    EXPECT_EQ(spec.priority(), server::kHealthPriority);
    ASSERT_EQ(spec.controller().open_loop_pwm().segments_size(), 2);
    EXPECT_EQ(spec.controller().open_loop_pwm().segments(0).duty(), 0.0);
    EXPECT_EQ(spec.controller().open_loop_pwm().segments(1).duty(), 1.0);
    EXPECT_DOUBLE_EQ(spec.duration_s(), server::kHealthDefaultDuration_s);
  }
  EXPECT_EQ(hold.name(), "health-hold-24V-400000Pa");
  EXPECT_EQ(hold.conditions().supply_v(), 24.0);
  EXPECT_EQ(hold.conditions().supply_pressure_pa(), 4e5);
  EXPECT_EQ(runs::NightNumberOf(hold), 12);
  EXPECT_EQ(hold.priority(), server::kHealthPriority);
  ASSERT_EQ(hold.controller().open_loop_pwm().segments_size(), 4);
  // A 5 ms baseline (the scope's offset), the switch-on as long as the others', then the PWM, then the drop-out.
  const double pull_in_s = server::kHealthDefaultDuration_s - server::kHealthPreTrigger_s;
  EXPECT_DOUBLE_EQ(hold.controller().open_loop_pwm().segments(1).start_s(), server::kHealthHoldBaseline_s);
  const auto& pwm = hold.controller().open_loop_pwm().segments(2);
  EXPECT_DOUBLE_EQ(pwm.start_s(), server::kHealthHoldBaseline_s + pull_in_s);
  EXPECT_EQ(pwm.duty(), server::kHealthDefaultHoldDuty);
  EXPECT_EQ(pwm.frequency_hz(), server::kHealthDefaultHoldFrequency_Hz);
  const auto& released = hold.controller().open_loop_pwm().segments(3);
  EXPECT_DOUBLE_EQ(released.start_s(), server::kHealthHoldBaseline_s + pull_in_s + server::kHealthDefaultHold_s);
  EXPECT_EQ(released.duty(), 0.0);
  EXPECT_DOUBLE_EQ(hold.duration_s(), server::kHealthHoldBaseline_s + pull_in_s + server::kHealthDefaultHold_s +
                                          server::kHealthDefaultDropOut_s);
  // dropout_s 0: the run ends with the hold; a drop-out shorter than 4 PWM periods is refused, naming the field.
  h->set_dropout_s(0.0);
  auto no_dropout = server::SettingsFromConfig(c, "");
  ASSERT_TRUE(no_dropout.ok()) << no_dropout.status().message();
  const auto held = server::HealthCheckSpecs(no_dropout->benches[0], "2026-11-29", 12).back();
  EXPECT_EQ(held.controller().open_loop_pwm().segments_size(), 3);
  EXPECT_DOUBLE_EQ(held.duration_s(), server::kHealthHoldBaseline_s + pull_in_s + server::kHealthDefaultHold_s);
  h->set_dropout_s(0.002);
  auto short_dropout = server::SettingsFromConfig(c, "");
  ASSERT_FALSE(short_dropout.ok());
  EXPECT_NE(short_dropout.status().message().find("health.dropout_s"), std::string::npos)
      << short_dropout.status().message();
  h->clear_dropout_s();
  // No hold when its duty is 0; a duty, frequency or length it cannot measure is refused, naming the field.
  h->set_hold_duty(0.0);
  auto no_hold = server::SettingsFromConfig(c, "");
  ASSERT_TRUE(no_hold.ok()) << no_hold.status().message();
  EXPECT_EQ(server::HealthCheckSpecs(no_hold->benches[0], "2026-11-29", 12).size(), 4u);
  h->set_hold_duty(1.0);
  auto bad = server::SettingsFromConfig(c, "");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("health.hold_duty"), std::string::npos) << bad.status().message();
  h->set_hold_duty(0.4);
  h->set_hold_frequency_hz(20e3);  // 5 samples a period at 100 kHz
  bad = server::SettingsFromConfig(c, "");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("health.hold_frequency_Hz"), std::string::npos) << bad.status().message();
  h->set_hold_frequency_hz(1e3);
  h->set_hold_s(0.005);  // 5 periods
  bad = server::SettingsFromConfig(c, "");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("health.hold_s"), std::string::npos) << bad.status().message();
  h->clear_hold_duty(), h->clear_hold_frequency_hz(), h->clear_hold_s();
  EXPECT_EQ(conditions.size(), 4u);
  // A bench without the block has no check.
  c.mutable_benches(0)->clear_health();
  auto none = server::SettingsFromConfig(c, "");
  ASSERT_TRUE(none.ok());
  EXPECT_TRUE(server::HealthCheckSpecs(none->benches[0], "2026-11-29", 1).empty());
}

// Where the anchor moved (a night's "anchor_refit" and "reidentified" blocks): the store's older records stay as
// they were, and the history read back has the earlier nights' values identified again from the moved anchor,
// from the newest night that moved it; the anchor itself comes back for a restart, and a block that is not an
// anchor is refused naming the field.
TEST(StoredHealth, TheNewestMovedAnchorsValuesStandForTheEarlierNights) {
  const std::string dir = ::testing::TempDir() + "/vb-twin-anchor-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  auto store = db::OpenSqliteStore(dir + "/store.db");
  ASSERT_TRUE(store.ok()) << store.status().message();
  auto values = [](const std::string& night, double R) {
    gap::SessionValues v;
    v.name = night;
    v.fit_rmse_A = 1e-3, v.noise_floor_A = 1e-3;
    gap::DeterminedValue d;
    d.name = "R", d.unit = "ohm", d.value = R, d.sigma = 0.1;
    v.determined.push_back(d);
    return nlohmann::json::parse(gap::SessionValuesJson(v));
  };
  server::StoredAnchor moved{"", "2026-11-01", {{"R", 61.0}, {"L0", 0.05}}, {"eddy_currents"}, 1};
  auto night = [&](const std::string& date, std::int64_t batch, double R, const nlohmann::json& extra) {
    nlohmann::json h = {{"bench", "emu"}, {"batch_id", batch}, {"values", values(date, R)}};
    for (const auto& [k, v] : extra.items()) h[k] = v;
    db::RegressionRecord rec;
    rec.suite = "nightly", rec.night = date, rec.verdict = "passed", rec.created_unix_s = 1.0;
    rec.result_json = nlohmann::json({{"health", nlohmann::json::array({h})}}).dump();
    ASSERT_TRUE((*store)->SaveRegression(rec).ok());
  };
  night("2026-11-01", 11, 60.0, nlohmann::json::object());
  night("2026-11-02", 12, 60.1, nlohmann::json::object());
  // Night 3 moved the anchor: nights 1 and 2 again (night 2's identification failed this time: the old stays).
  auto failed = values("2026-11-02", 0.0);
  failed["error"] = "not identified";
  night("2026-11-03", 13, 61.2,
        {{"anchor_refit", server::StoredAnchorJson(moved)},
         {"reidentified", nlohmann::json::array({values("2026-11-01", 61.0), failed})}});
  night("2026-11-04", 14, 61.3, nlohmann::json::object());
  auto h = server::LoadStoredHealth(store->get());
  ASSERT_TRUE(h.ok()) << h.status().message();
  const auto& emu = h->values.at("emu");
  ASSERT_EQ(emu.size(), 4u);
  EXPECT_EQ(emu.at("2026-11-01").determined.at(0).value, 61.0) << "identified again from the moved anchor";
  EXPECT_EQ(emu.at("2026-11-02").determined.at(0).value, 60.1) << "a failed re-identification keeps the stored";
  EXPECT_EQ(emu.at("2026-11-03").determined.at(0).value, 61.2);
  ASSERT_TRUE(h->anchor.count("emu"));
  EXPECT_EQ(h->anchor.at("emu").night, "2026-11-03");
  EXPECT_EQ(h->anchor.at("emu").anchor_night, "2026-11-01");
  EXPECT_EQ(h->anchor.at("emu").fitted.at("R"), 61.0);
  EXPECT_EQ(h->anchor.at("emu").effects, std::vector<std::string>{"eddy_currents"});
  EXPECT_EQ(h->anchor.at("emu").moves, 1);
  EXPECT_EQ(h->first_check.at("emu").second, 11);
  // Before night 3 (the server's view on night 3 itself), nothing had moved.
  auto before = server::LoadStoredHealth(store->get(), "2026-11-03");
  ASSERT_TRUE(before.ok());
  EXPECT_EQ(before->values.at("emu").at("2026-11-01").determined.at(0).value, 60.0);
  EXPECT_FALSE(before->anchor.count("emu"));

  auto bad = server::StoredAnchorJson(moved);
  bad["fitted"]["R"] = "sixty";
  auto parsed = server::StoredAnchorFromJson(bad);
  ASSERT_FALSE(parsed.ok());
  EXPECT_NE(parsed.status().message().find("anchor_refit.fitted.R: not a number"), std::string::npos)
      << parsed.status().message();
  bad = server::StoredAnchorJson(moved);
  bad["moves"] = 1e12;
  EXPECT_NE(server::StoredAnchorFromJson(bad).status().message().find("anchor_refit.moves"), std::string::npos);
  EXPECT_NE(server::StoredAnchorFromJson("not an anchor").status().message().find("anchor_refit: not an object"),
            std::string::npos);
  // A night whose blocks are not what the server writes is read as if they were absent, and nothing is lost.
  night("2026-11-05", 15, 61.4,
        {{"anchor_refit", "garbage"}, {"reidentified", nlohmann::json::array({1, "x", nullptr})}});
  night("2026-11-06", 16, 61.5, {{"anchor_refit", server::StoredAnchorJson(moved)}, {"reidentified", 7}});
  auto odd = server::LoadStoredHealth(store->get());
  ASSERT_TRUE(odd.ok()) << odd.status().message();
  EXPECT_EQ(odd->values.at("emu").size(), 6u);
  EXPECT_EQ(odd->values.at("emu").at("2026-11-01").determined.at(0).value, 61.0) << "night 3's still stand";
  EXPECT_EQ(odd->anchor.at("emu").night, "2026-11-03");
  std::filesystem::remove_all(dir);
}

// The valve a baseline was measured on: the bench's last checked night that started before the baseline was
// made; none (the first night stands for it) when the baseline is older than every check or has no time.
TEST(BaselineNight, TheLastCheckedNightThatStartedBeforeTheBaselineWasMade) {
  const std::map<std::string, server::StoredCheck> checks = {
      {"2026-11-01", {1000.0, 11}}, {"2026-11-02", {2000.0, 12}}, {"2026-11-03", {0.0, 13}}, {"2026-11-04", {4000.0, 14}}};
  EXPECT_FALSE(server::BaselineNight(checks, 500.0));  // older than every check
  EXPECT_FALSE(server::BaselineNight(checks, 0.0));    // time not known
  EXPECT_FALSE(server::BaselineNight({}, 3000.0));
  auto b = server::BaselineNight(checks, 2500.0);  // set from night 2's batch the morning after
  ASSERT_TRUE(b);
  EXPECT_EQ(b->first, "2026-11-02");
  EXPECT_EQ(b->second.batch_id, 12);
  b = server::BaselineNight(checks, 3999.0);  // night 3 recorded no start: night 2 stays the last known before
  ASSERT_TRUE(b);
  EXPECT_EQ(b->first, "2026-11-02");
  b = server::BaselineNight(checks, 9000.0);
  ASSERT_TRUE(b);
  EXPECT_EQ(b->first, "2026-11-04");
}

// A regressed metric's cause from its replay (server::DecideCase), each rule on values: the valve when it makes
// half the change; the code when its part is within the allowance by twice the replay's repeatability and the
// tracking saw no change; otherwise "undetermined", saying which of the three reasons holds.
TEST(DecideCase, ValveCodeOrWhyItCannotTell) {
  EXPECT_EQ(server::DecideCase(-39.0, 0.5, -33.0, 0.3, "").verdict, "valve");
  EXPECT_EQ(server::DecideCase(-39.0, 0.5, -33.0, 0.3, "bench a's R up since x").verdict, "valve");
  EXPECT_EQ(server::DecideCase(2.5e-3, 2.9e-4, 3e-6, 1.5e-5, "").verdict, "code");
  // The 60-night lab's nights 25 and 22 (third run, 2026-11-30): the PI hold's code night, tonight's valve
  // replayed 0.19 mA off what the bench measured against 0.78 allowed: code. The map on a valve 1 % warmer
  // before the flag: the replay's part -0.24 points, but the replay 6.7 points off the bench: not code.
  EXPECT_EQ(server::DecideCase(3.4e-3, 7.8e-4, -6.4e-5, 1.2e-5, "", -1.9e-4).verdict, "code");
  const auto off = server::DecideCase(-4.47, 0.5, -0.236, 0.042, "", 6.74);
  EXPECT_EQ(off.verdict, "undetermined");
  EXPECT_NE(off.why.find("replays this case 6.74 off what the bench measured tonight"), std::string::npos) << off.why;
  // The lab's relaxing spring: the replay near full opening barely moves, the bench's valve did.
  const auto flagged = server::DecideCase(1.73, 0.5, 0.106, 0.019, "bench emu-2's F0*x_max down since 2026-11-01");
  EXPECT_EQ(flagged.verdict, "undetermined");
  EXPECT_NE(flagged.why.find("the valve changed since the baseline (bench emu-2's F0*x_max down"), std::string::npos)
      << flagged.why;
  // An operating edge: the part is small, the repeatability is not.
  const auto edge = server::DecideCase(-28.5, 0.5, 0.44, 18.6, "");
  EXPECT_EQ(edge.verdict, "undetermined");
  EXPECT_NE(edge.why.find("the replay cannot resolve the valve's part here"), std::string::npos) << edge.why;
  // Beyond the allowance and under half the change: both.
  const auto both = server::DecideCase(-10.0, 0.5, -3.0, 0.1, "");
  EXPECT_EQ(both.verdict, "undetermined");
  EXPECT_NE(both.why.find("both changed"), std::string::npos) << both.why;
}

// The same with the baseline's code replayed (server::DecideCase(CaseReplay)): the 60-night lab's night 25 on
// values (the PI law's gain cut on a bench whose R the tracking flagged): tonight's code on the baseline's valve
// makes the change, tonight's valve under the baseline's code does not: "code", the flag said in the reason. A
// spec change the metric does not see leaves the rules above; each undetermined outcome says which parts reach.
TEST(DecideCase, TheBaselinesCodeOnBothValves) {
  const std::string flag = "bench emu-1's R up since 2026-10-21";
  server::CaseReplay r{2.4e-3, 1.0e-4, 1.2e-4, 2e-5, flag};
  EXPECT_EQ(server::DecideCase(r).verdict, "undetermined");  // the baseline's code not known: as before
  r.baseline_code_known = true;
  r.code_change = 2.3e-3;
  r.valve_change_baseline_code = 5e-6;
  r.sigma_baseline_code = 2e-6;
  const auto code = server::DecideCase(r);
  EXPECT_EQ(code.verdict, "code");
  EXPECT_NE(code.why.find("the valve changed since the baseline (" + flag), std::string::npos) << code.why;
  EXPECT_NE(code.why.find("under the baseline's code tonight's valve makes 0 % of the change (5e-06)"),
            std::string::npos) << code.why;
  r.valve_change_baseline_code = -2e-4;  // against the failure (the good law on a warmer coil): none of it
  EXPECT_EQ(server::DecideCase(r).verdict, "code");
  r.valve_change_baseline_code = 5e-6;
  r.sigma_baseline_code = 7e-4;  // the valve's part, 2 sigma toward the failure, could make half of it
  EXPECT_NE(server::DecideCase(r).why.find("the replay cannot resolve whether the valve makes half"),
            std::string::npos) << server::DecideCase(r).why;
  r.sigma_baseline_code = 2e-6;
  r.valve_change_baseline_code = 1.5e-3;  // each alone makes half
  EXPECT_NE(server::DecideCase(r).why.find("both changed: tonight's code on the baseline's valve makes 96 %"),
            std::string::npos) << server::DecideCase(r).why;
  r.code_change = 3e-4;  // beyond the allowance, under half: the valve's
  EXPECT_EQ(server::DecideCase(r).verdict, "valve");
  r.valve_change_baseline_code = 5e-4;  // and neither makes half
  EXPECT_NE(server::DecideCase(r).why.find("neither makes half the change alone"), std::string::npos);
  r.valve_change_baseline_code = 5e-6;  // the valve's part none, the code's under half: the code, unless flagged
  EXPECT_EQ(server::DecideCase(r).verdict, "undetermined");
  r.changed_since_baseline.clear();
  EXPECT_EQ(server::DecideCase(r).verdict, "code");
  r.changed_since_baseline = flag;
  r.code_change = 8e-5;  // within the allowance: another seed's jitter, not a change this metric sees
  r.valve_change = 2e-5;
  EXPECT_NE(server::DecideCase(r).why.find("the code changed too, or the replay misses"), std::string::npos)
      << "flagged: the rules above";
  r.changed_since_baseline.clear();
  EXPECT_EQ(server::DecideCase(r).verdict, "code");

  // The spec is the baseline's (the 60-night lab's fourth run, the relaxing spring's map nights): the valve alone
  // moves the map 1.13 points toward the failure of 2.52 (45 %), beyond the 0.5 allowed by more than twice its
  // repeatability 0.12: the valve, the rest being the replay's distance from the bench. Within 2 sigma of the
  // allowance, or against the failure, the rules above.
  server::CaseReplay same{2.52, 0.5, 1.13, 0.12, ""};
  same.replay_off_tonight = 0.0;
  EXPECT_EQ(server::DecideCase(same).verdict, "undetermined");  // not known to be the baseline's spec
  same.spec_is_baseline_code = true;
  const auto spring = server::DecideCase(same);
  EXPECT_EQ(spring.verdict, "valve");
  EXPECT_NE(spring.why.find("the valve alone moves this metric 1.13 toward the failure (45 % of the change"),
            std::string::npos) << spring.why;
  same.sigma = 0.35;
  EXPECT_EQ(server::DecideCase(same).verdict, "undetermined");
  same.sigma = 0.12;
  same.valve_change = -1.13;
  EXPECT_EQ(server::DecideCase(same).verdict, "undetermined");
}

// The spec and the build that ran it are the baseline's: no code changed, so the bench did, whatever the replay
// reads (the cases above that it leaves undetermined: the replay off the bench, a flagged valve's small part, an
// operating edge). A spec or a build that differs, or one not known, leaves the replay's rules.
TEST(DecideCase, TheBaselinesSpecAndBuildLeaveOnlyTheBench) {
  server::CaseReplay r{-4.47, 0.5, -0.236, 0.042, ""};
  r.replay_off_tonight = 6.74;
  r.spec_is_baseline_code = true;
  EXPECT_EQ(server::DecideCase(r).verdict, "undetermined") << "the spec alone: a build may have changed";
  r.build_is_baseline = true;
  const auto warm = server::DecideCase(r);
  EXPECT_EQ(warm.verdict, "valve");
  EXPECT_NE(warm.why.find("the spec and the build that ran it are the baseline's code's: no code changed, the "
                          "bench did"),
            std::string::npos) << warm.why;
  EXPECT_NE(warm.why.find("replays only 5 % of the change and the tracking flagged nothing"), std::string::npos)
      << warm.why;
  r.valve_change = 0.9;  // the lab's night 21 (--baseline-night 2): the replay moves the map the other way
  EXPECT_NE(server::DecideCase(r).why.find("replays the change the other way (-20 %)"), std::string::npos)
      << server::DecideCase(r).why;
  r.valve_change = -0.236;
  r.changed_since_baseline = "bench emu-2's F0*x_max down since 2026-11-01";
  EXPECT_NE(server::DecideCase(r).why.find("bench emu-2's F0*x_max down since 2026-11-01; its identified valve "
                                           "replays 5 %"),
            std::string::npos) << server::DecideCase(r).why;
  r.valve_change = -4.0;
  EXPECT_NE(server::DecideCase(r).why.find("tonight's identified valve replays 89 % of the change"), std::string::npos);
  // A spec that differs (a build that matches says nothing then): both codes on both valves decide. Tonight's code
  // on the baseline's valve makes 94 % of the change, tonight's valve under the baseline's code none: the code.
  r.spec_is_baseline_code = false;
  r.baseline_code_known = true;
  r.code_change = -4.2;
  r.valve_change_baseline_code = 0.01;
  r.sigma_baseline_code = 0.01;
  EXPECT_EQ(server::DecideCase(r).verdict, "code") << server::DecideCase(r).why;
}

// A case's build is the one build all its runs recorded; a run without one, or two builds, leave none.
TEST(CaseBuilds, OneBuildForAllTheCasesRunsOrNone) {
  server::CaseBuilds b;
  server::AddCaseBuild(&b, "hold", "valvebench 0.1.0 sha256:aa");
  server::AddCaseBuild(&b, "hold", "valvebench 0.1.0 sha256:aa");
  server::AddCaseBuild(&b, "map", "valvebench 0.1.0 sha256:aa");
  server::AddCaseBuild(&b, "map", "valvebench 0.1.0 sha256:bb");
  server::AddCaseBuild(&b, "map", "valvebench 0.1.0 sha256:aa");
  server::AddCaseBuild(&b, "step", "valvebench 0.1.0 sha256:aa");
  server::AddCaseBuild(&b, "step", "");
  server::AddCaseBuild(&b, "step", "valvebench 0.1.0 sha256:aa");
  server::AddCaseBuild(&b, "late", "");
  server::AddCaseBuild(&b, "late", "valvebench 0.1.0 sha256:aa");
  EXPECT_EQ(b["hold"], "valvebench 0.1.0 sha256:aa");
  EXPECT_EQ(b["map"], "");
  EXPECT_EQ(b["step"], "");
  EXPECT_EQ(b["late"], "");
}

// Attribute on a case whose bench has no identified check tonight (nothing to replay): the same spec and build as
// the baseline's code make it the bench's, saying it was not replayed; the same spec on another build is
// undetermined and names both builds (a code change the spec does not show, which this server cannot replay).
TEST(BenchTwin, WithoutAReplayTheSpecAndBuildStillDecideAndABuildChangeIsSaid) {
  server::BenchTwins twins(nullptr);
  regress::RegressResult result;
  regress::Finding f;
  f.case_name = "map";
  f.metric = "mean_position_pct";
  f.verdict = regress::Verdict::kRegressed;
  f.baseline.mean = 97.5;
  f.now.mean = 93.0;
  f.delta = -4.5;
  f.allowed = 0.5;
  result.findings.push_back(f);
  const std::map<std::string, experiment::ExperimentSpec> specs{{"map", experiment::ExperimentSpec{}}};
  const std::map<std::string, std::vector<std::string>> benches{{"map", {"emu-a"}}};
  server::BaselineCode baseline;
  baseline.specs["map"] = experiment::ExperimentSpec{};
  baseline.from = "the baseline's batch 7";
  baseline.builds["map"] = "valvebench 0.1.0 sha256:aa";
  auto same = twins.Attribute(result, specs, benches, baseline, {{"map", "valvebench 0.1.0 sha256:aa"}});
  ASSERT_EQ(same["cases"].size(), 1u) << same.dump(1);
  EXPECT_EQ(same["verdict"], "valve") << same.dump(1);
  EXPECT_NE(same["cases"][0].value("reason", "").find("no code changed, the bench did (not replayed: bench emu-a "
                                                      "ran it and has no identified health check tonight"),
            std::string::npos) << same.dump(1);
  EXPECT_EQ(same["cases"][0].value("baseline_code", ""), "the baseline's batch 7");
  auto other = twins.Attribute(result, specs, benches, baseline, {{"map", "valvebench 0.1.0 sha256:bb"}});
  EXPECT_EQ(other["verdict"], "undetermined") << other.dump(1);
  EXPECT_NE(other["cases"][0].value("reason", "").find("the spec is the baseline's code's but the build is not "
                                                       "(valvebench 0.1.0 sha256:aa -> valvebench 0.1.0 sha256:bb)"),
            std::string::npos) << other.dump(1);
  auto unknown = twins.Attribute(result, specs, benches, baseline, {{"map", ""}});
  EXPECT_EQ(unknown["verdict"], "undetermined") << unknown.dump(1);
  EXPECT_EQ(unknown["cases"][0].value("reason", "").find("build"), std::string::npos) << unknown.dump(1);
}

// Waits until the server has stored `n` nights; returns them newest first (an empty array on timeout).
nlohmann::json WaitForNights(const std::string& addr, std::size_t n, int timeout_s) {
  const std::string cmd =
      std::string(VB_BENCHCTL) + " nights --json --limit 100 --server " + addr + " --token " + testing::kViewerToken;
  nlohmann::json list = nlohmann::json::array();
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(timeout_s);
  while (std::chrono::steady_clock::now() < until) {
    const auto r = testing::RunCommand(cmd);
    const size_t at = r.out.find('[');
    list = nlohmann::json::parse(at == std::string::npos ? std::string() : r.out.substr(at), nullptr, false);
    if (list.is_array() && list.size() >= n) return list;
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
  }
  // Not done in time: what the queue holds (a run that never ends, or runs nobody took) for the failure's reader.
  const auto queue = testing::RunCommand(std::string(VB_BENCHCTL) + " queue --server " + addr + " --token " +
                                         testing::kViewerToken);
  std::fprintf(stderr, "%zu of %zu nights after %d s; the queue:\n%s\n", list.is_array() ? list.size() : 0, n,
               timeout_s, queue.out.c_str());
  return nlohmann::json::array();
}

const char kHealth[] =
    R"("health": {"supply_V": [24, 20], "supply_pressure_Pa": [100000, 250000, 400000]}, "current_noise_A": 0.002)";

// A bench lives nine nights in one start (--simulate-nights 9) and its coil's resistance is 15 % higher from
// night 6 (a corroding connector: the suite's map no longer opens the valve fully at duty 0.3, and the PI hold
// needs more voltage). The server identifies each night's health check, tracks the bench over its stored nights
// and, for the regressed nights, replays the failing case on the emulator with the bench's first-night valve and
// tonight's valve under the same code: nights 1-5 pass with no valve change, nights 6-9 regress with the cause
// "valve" (by the build and the spec, both the first night's, which reproduced the baseline: nothing that runs as
// code changed), and R is named since night 6 by night 9 at the latest. Why night 9: the tracking's reference is the
// first five nights (TrackOptions::min_reference), so its self-starting z is a t with four degrees of freedom,
// at most about 4-5 however large the step; z enters the CUSUM clipped at 3 unless the night before was also
// beyond 3 (docs/track.md, "Outliers"): 2.5, then about 4 and 3.5 a night against h = 8.74.
// GetBenchHealth and benchctl health say the same.
TEST(BenchTwin, AValveThatChangedIsNamedAsTheCauseOfTheRegressedNights) {
  constexpr int kNights = 9, kChange = 5;  // the change's night, 0-based
  const std::string dir = ::testing::TempDir() + "/vb-twin-valve-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  const std::string benches = R"([{"name": "emu-a", "kind": "emulated", "model": {"preset": "taghizadeh2009"}, )" +
                              std::string(kHealth) +
                              R"(, "drift": [{"parameter": "R", "step": 0.15, "from_night": 6}]}])";
  const std::string nights = R"("nights": {"cron": "0 2 * * *", "suite_file": ")" + kSuites +
                             R"(ci.json", "baseline_file": ")" + kSuites + R"(ci-baseline.json", "timezone": "UTC"})";
  testing::ServerProcess server(dir, nights, benches);
  server.AddArg("--simulate-nights");
  server.AddArg(std::to_string(kNights));
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  nlohmann::json list = WaitForNights(addr, kNights, 280);
  ASSERT_EQ(list.size(), static_cast<std::size_t>(kNights)) << server.Log();
  std::reverse(list.begin(), list.end());  // oldest first
  std::vector<std::string> dates;
  for (const auto& n : list) dates.push_back(n["date"]);

  // The server's own tracking, as every door reads it (GetBenchHealth): read first, so that every failure below
  // shows it (each night's fit, values and z) with the server's log (the nights' identifications and flags).
  client::ClientOptions o;
  o.address = addr;
  o.token = testing::kViewerToken;
  client::Client c(o);
  auto served = c.GetBenchHealth("emu-a");
  ASSERT_TRUE(served.ok()) << served.status().message();
  ASSERT_EQ(served->benches_size(), 1);
  const auto& bh = served->benches(0);
  const std::string why = "\n" + bh.report() + "\n" + server.Log();
  for (int k = 0; k < kChange; ++k) {
    EXPECT_EQ(list[k]["verdict"], "passed") << list[k].dump(1);
    EXPECT_TRUE(list[k]["valve_changes"].empty()) << list[k].dump(1) << why;
    EXPECT_EQ(list[k]["cause"], "") << list[k].dump(1);
  }
  for (int k = kChange; k < kNights; ++k) {
    EXPECT_EQ(list[k]["verdict"], "regressed") << list[k].dump(1);
    EXPECT_EQ(list[k]["cause"], "valve") << list[k].dump(1) << why;
    // The baseline file was made elsewhere, so its code is the first night's suite (the night rule), which
    // compared with it and passed: that night's spec and build ran tonight too, so no code changed.
    EXPECT_NE(list[k]["cause_reason"].get<std::string>().find("of the baseline's code (night " + dates[0] +
                                                               "'s suite, batch "),
              std::string::npos)
        << list[k].dump(1);
    if (k < kNights - 1 && list[k]["valve_changes"].empty()) continue;  // not summed past h yet (above)
    ASSERT_FALSE(list[k]["valve_changes"].empty()) << list[k].dump(1) << why;
    // The resistance, by the switch-on's identification (R) or by the hold (R_hold, the more precise: it is
    // flagged on the same night with the larger z, so it comes first).
    const std::string first = list[k]["valve_changes"][0];
    EXPECT_TRUE(first.rfind("emu-a: R up", 0) == 0u || first.rfind("emu-a: R_hold up", 0) == 0u) << first;
    EXPECT_NE(first.find("since " + dates[kChange]), std::string::npos) << first;
  }
  EXPECT_EQ(std::vector<std::string>(bh.nights().begin(), bh.nights().end()), dates);
  ASSERT_GT(bh.flags_size(), 0) << why;
  EXPECT_TRUE(bh.flags(0).parameter() == "R" || bh.flags(0).parameter() == "R_hold") << bh.report();
  EXPECT_EQ(bh.flags(0).since(), dates[kChange]) << bh.report();
  EXPECT_LE(bh.flags(0).night(), dates[kNights - 1]) << bh.report();
  std::set<std::string> tracked;
  for (const auto& p : bh.parameters()) {
    tracked.insert(p.name());
    EXPECT_EQ(p.value_size(), kNights) << p.name();
    if (p.name() == "R_hold") {
      // The hold sees the winding's 15 % at once, and nothing else moves it: flagged on the change's night's
      // first sessions after the reference, never before.
      EXPECT_EQ(p.flagged_night(), bh.flags(0).night());
      EXPECT_GE(p.flagged_night(), dates[kChange]);
    }
    if (p.name() == "L_hold") {
      EXPECT_TRUE(p.flagged_night().empty()) << bh.report();
    }
  }
  EXPECT_TRUE(tracked.count("R") && tracked.count("R_hold") && tracked.count("L_hold") && tracked.count("i_dropout"))
      << bh.report();
  EXPECT_NE(bh.report().find("FLAG"), std::string::npos) << bh.report();
  auto unknown = c.GetBenchHealth("emu-c");
  EXPECT_EQ(unknown.status().code(), StatusCode::kNotFound) << unknown.status().message();
  auto huge = c.GetBenchHealth(std::string(100000, 'a'));  // echoed whole, it overflowed the status metadata
  EXPECT_EQ(huge.status().code(), StatusCode::kInvalidArgument) << huge.status().message();
  EXPECT_EQ(huge.status().message().rfind("bench: 100000 bytes", 0), 0u) << huge.status().message().substr(0, 200);

  const auto r = testing::RunCommand(std::string(VB_BENCHCTL) + " health --json --server " + addr + " --token " +
                                     testing::kViewerToken);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  const auto j = nlohmann::json::parse(r.out.substr(std::min(r.out.find('{'), r.out.size())), nullptr, false);
  ASSERT_TRUE(j.is_object()) << r.out;
  ASSERT_EQ(j["benches"].size(), 1u) << j.dump(1);
  EXPECT_EQ(j["benches"][0]["sessions"], dates) << j.dump(1);
  ASSERT_FALSE(j["flags"].empty()) << j.dump(1);
  EXPECT_EQ(j["flags"][0]["bench"], "emu-a");
  EXPECT_TRUE(j["flags"][0]["parameter"] == "R" || j["flags"][0]["parameter"] == "R_hold") << j["flags"].dump(1);
  EXPECT_EQ(j["flags"][0]["since"], dates[kChange]) << j["flags"].dump(1);
  EXPECT_NEAR(j["flags"][0]["change_relative"].get<double>(), 0.15, 0.02) << j["flags"][0].dump(1);
  for (const auto& f : j["flags"]) EXPECT_GE(f["session"].get<std::string>(), dates[kChange]) << f.dump();
  EXPECT_EQ(j["source"], "the server's nights");
  // A bench without checks: exit 2, named.
  const auto missing = testing::RunCommand(std::string(VB_BENCHCTL) + " health emu-c --server " + addr +
                                           " --token " + testing::kViewerToken);
  EXPECT_EQ(missing.exit_code, 2) << missing.out;
  EXPECT_NE(missing.out.find("no health checks stored for bench emu-c"), std::string::npos) << missing.out;

  // The nights as JUnit XML (a CI's page): the newest night fails with its cause first and the valve change.
  const std::string xml_path = dir + "/nights.xml";
  const auto junit = testing::RunCommand(std::string(VB_BENCHCTL) + " nights --junit " + xml_path + " --server " +
                                         addr + " --token " + testing::kViewerToken);
  EXPECT_EQ(junit.exit_code, 1) << junit.out;  // the newest night regressed
  std::ifstream in(xml_path);
  const std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto night = xml.find("name=\"" + dates[kNights - 1] + "\"");
  ASSERT_NE(night, std::string::npos) << xml;
  EXPECT_EQ(xml.find("<failure type=\"regression\" message=\"cause: valve (", night), xml.find("<failure", night)) << xml;
  EXPECT_NE(xml.find("valve changed: emu-a: R", night), std::string::npos) << xml;
  EXPECT_NE(xml.find("failures=\"" + std::to_string(kNights - kChange) + "\""), std::string::npos) << xml;
}

// The same bench without drift, under a suite whose PI law's proportional gain was cut tenfold (nights_test's
// worse controller): every night regresses, the valve is not seen to change, and the cause is "code" (tonight's
// identified valve, under the same code, stays within the suite's allowance against the first night's). And
// `benchctl health --recompute` identifies the same checks again on the client: nothing flagged, exit 0.
TEST(BenchTwin, ACodeRegressionOnAnUnchangedValveIsNamedAsTheCode) {
  const std::string dir = ::testing::TempDir() + "/vb-twin-code-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  ASSERT_EQ(testing::WriteWorseCiSuite(kSuites, dir), "");
  const std::string benches = R"([{"name": "emu-a", "kind": "emulated", "model": {"preset": "taghizadeh2009"}, )" +
                              std::string(kHealth) + "}]";
  testing::ServerProcess server(dir, R"("nights": {"cron": "0 2 * * *", "suite_file": "ci.json", "baseline_file": ")" +
                                         kSuites + R"(ci-baseline.json"})", benches);
  server.AddArg("--simulate-nights");
  server.AddArg("3");
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  const nlohmann::json list = WaitForNights(addr, 3, 180);
  ASSERT_EQ(list.size(), 3u) << server.Log();
  for (const auto& n : list) {
    EXPECT_EQ(n["verdict"], "regressed") << n.dump(1);
    EXPECT_EQ(n["cause"], "code") << n.dump(1) << "\n" << server.Log();
    EXPECT_TRUE(n["valve_changes"].empty()) << n.dump(1);
  }
  const auto junit = testing::RunCommand(std::string(VB_BENCHCTL) + " nights --junit " + dir + "/nights.xml --server " +
                                         addr + " --token " + testing::kViewerToken);
  EXPECT_EQ(junit.exit_code, 1) << junit.out;
  std::ifstream in(dir + "/nights.xml");
  const std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(xml.find("<failure type=\"regression\" message=\"cause: code ("), std::string::npos) << xml;
  EXPECT_NE(xml.find(R"(tests="3" failures="3")"), std::string::npos) << xml;
  const auto again = testing::RunCommand(std::string(VB_BENCHCTL) + " health emu-a --recompute --json --server " +
                                         addr + " --token " + testing::kViewerToken);
  EXPECT_EQ(again.exit_code, 0) << again.out;
  const auto k = nlohmann::json::parse(again.out.substr(std::min(again.out.find('{'), again.out.size())), nullptr, false);
  ASSERT_TRUE(k.is_object()) << again.out;
  EXPECT_EQ(k["source"], "identified here");
  ASSERT_EQ(k["benches"].size(), 1u) << k.dump(1);
  EXPECT_EQ(k["benches"][0]["sessions"].size(), 3u) << k.dump(1);
  EXPECT_TRUE(k["flags"].empty()) << k.dump(1);
}

// The 60-night lab's night 25 (docs/track.md): the PI law's gain cut tenfold on a bench whose coil's resistance
// the tracking has flagged. The bench's R is 5 % higher from night 6; once night 9 is stored (R flagged by then,
// as in AValveThatChangedIsNamedAsTheCauseOfTheRegressedNights) the suite's PI hold is swapped for the worse one.
// Every night that ran it regresses on the PI hold's RMSE, and that metric's cause is `code`, the flag named in
// its reason: the baseline's code (the first night's suite, the baseline file being older than every night) on
// tonight's valve does not reproduce the failure, tonight's code on the first night's valve does. Before the
// baseline's code was replayed this said `undetermined` (the flag was not overruled by the replay's small part).
TEST(BenchTwin, ACodeRegressionOnAFlaggedValveIsTheCodesWhenTheBaselinesCodeDoesNotReproduceIt) {
  constexpr int kNights = 12, kSwapAfter = 9;
  const std::string dir = ::testing::TempDir() + "/vb-twin-flagged-code-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  for (const char* f : {"ci.json", "ci-current-hold.json"}) std::filesystem::copy_file(kSuites + f, dir + "/" + f);
  {
    // The baseline as another lab's server made it: its source names batch 1, which on this server is the first
    // night's, not the baseline's runs. Its code is then the first night's suite (the night rule), the mismatch
    // said; before, that batch's specs were taken as the baseline's code.
    std::ifstream in(kSuites + "ci-baseline.json");
    auto b = nlohmann::json::parse(in);
    b["source"] = "server other-lab:50051 batch 1";
    std::ofstream(dir + "/baseline.json") << b.dump(1);
  }
  const std::string benches = R"([{"name": "emu-a", "kind": "emulated", "model": {"preset": "taghizadeh2009"}, )" +
                              std::string(kHealth) +
                              R"(, "drift": [{"parameter": "R", "step": 0.05, "from_night": 6}]}])";
  testing::ServerProcess server(
      dir, R"("nights": {"cron": "0 2 * * *", "suite_file": "ci.json", "baseline_file": "baseline.json"})", benches);
  server.AddArg("--simulate-nights");
  server.AddArg(std::to_string(kNights));
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  ASSERT_EQ(WaitForNights(addr, kSwapAfter, 300).size(), static_cast<std::size_t>(kSwapAfter)) << server.Log();
  ASSERT_EQ(testing::WriteWorseCiSuite(kSuites, dir + "/worse"), "");
  std::filesystem::rename(dir + "/worse/ci-current-hold.json", dir + "/ci-current-hold.json");
  ASSERT_EQ(WaitForNights(addr, kNights, 200).size(), static_cast<std::size_t>(kNights)) << server.Log();

  // Each night's whole record (its cause per regressed metric), from the server's store.
  auto store = db::OpenSqliteStore(server.db_path());
  ASSERT_TRUE(store.ok()) << store.status().message();
  auto briefs = (*store)->ListRegressions(/*nights_only=*/true, 100);
  ASSERT_TRUE(briefs.ok()) << briefs.status().message();
  int code_nights = 0, flagged_code_nights = 0;
  for (const auto& b : *briefs) {
    auto rec = (*store)->GetRegression(b.id);
    ASSERT_TRUE(rec.ok()) << rec.status().message();
    const auto j = nlohmann::json::parse(rec->result_json);
    if (!j.contains("cause")) continue;
    for (const auto& c : j["cause"]["cases"]) {
      // The map at duty 0.3 on the warmer coil opens less (the valve's change), near the edge where the valve
      // identified from its switch-on current is not the bench: where that leaves it undetermined, it says so.
      if (c["verdict"] == "undetermined" &&
          std::abs(c.value("replay_minus_measured_tonight", 0.0)) > c["allowed"].get<double>()) {
        EXPECT_NE(c.value("reason", "").find("the replay is not the bench here"), std::string::npos) << c.dump(1);
      }
      if (c["case"] != "hold/pi" || c["metric"] != "rmse" || c["observed_change"].get<double>() < 1e-3) continue;
      ++code_nights;  // the cut gain's RMSE: 0.8 mA -> about 3 mA
      EXPECT_EQ(c["verdict"], "code") << b.night << ": " << c.dump(1) << "\n" << server.Log();
      EXPECT_NE(c.value("baseline_code", "").find("'s suite, batch"), std::string::npos) << c.dump(1);
      EXPECT_EQ(c.value("baseline_code", "").rfind("the baseline's source names batch 1, which is not the "
                                                   "baseline's here (case ", 0), 0u) << c.dump(1);
      // The flag on the resistance: the switch-on's R or the hold's R_hold (the first, the larger z).
      if (c.value("reason", "").find("the valve changed since the baseline (bench emu-a's R") != std::string::npos)
        ++flagged_code_nights;
    }
  }
  EXPECT_GE(code_nights, 2) << "nights 11 and 12 at least read the worse suite";
  EXPECT_GE(flagged_code_nights, 2) << server.Log();
}

// A lab's own baseline: `benchctl baseline set NAME --batch BATCH` on the server, written over the baseline file
// the nights read (beside and renamed into place: a night never reads half a file). "" or what went wrong.
std::string SetBaselineFromBatch(const std::string& addr, const std::string& name, std::int64_t batch,
                                 const std::string& path) {
  const auto set = testing::RunCommand(std::string(VB_BENCHCTL) + " baseline set " + name + " --batch " +
                                       std::to_string(batch) + " --json --server " + addr + " --token " +
                                       testing::kOperatorToken);
  if (set.exit_code != 0 || set.out.find('{') == std::string::npos) return "benchctl baseline set: " + set.out;
  std::ofstream(path + ".new") << set.out.substr(set.out.find('{'));
  std::filesystem::rename(path + ".new", path);
  return "";
}

// A lab directory with the examples' ci suite and baseline file (the nights' config kLabNights reads them), and
// one emulated bench of the preset valve, checked each night, whose R steps up by `step` from `from_night`.
std::string TwinLabDir(const std::string& name) {
  const std::string dir = ::testing::TempDir() + "/vb-twin-" + name + "-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  for (const char* f : {"ci.json", "ci-current-hold.json"}) std::filesystem::copy_file(kSuites + f, dir + "/" + f);
  std::filesystem::copy_file(kSuites + "ci-baseline.json", dir + "/baseline.json");
  return dir;
}
std::string ResistanceStepBench(double step, int from_night) {
  return R"([{"name": "emu-a", "kind": "emulated", "model": {"preset": "taghizadeh2009"}, )" + std::string(kHealth) +
         R"(, "drift": [{"parameter": "R", "step": )" + std::to_string(step) + R"(, "from_night": )" +
         std::to_string(from_night) + "}]}]";
}
constexpr char kLabNights[] =
    R"("nights": {"cron": "0 2 * * *", "suite_file": "ci.json", "baseline_file": "baseline.json"})";

// A lab re-baselines after its valve changed: the failure after that is the code's, not the valve's. The bench's
// R is 15 % higher from night 2 (the map at duty 0.3 opens 58 % where it opened 97 %: those nights say `valve`);
// once night 3 is stored the lab sets a baseline from night 3's suite batch on the server and points the nights
// at it, and the same change cuts the PI law's proportional gain tenfold (code). Every night judged against the
// new baseline regresses on the PI hold's RMSE (0.76 mA on this valve with the good law, 3.23 mA with the cut
// one, by `benchctl run --local` with R x 1.15) and says `code`: the replay compares tonight's valve with the
// valve of the baseline's night (both 15 % up). Against the first night's valve, as before, the valve's part of
// the change would be 3.23 - 4.20 = -0.97 mA, 40 % of the change against it and far beyond the suite's allowance
// (5 % of 0.76 mA): `undetermined`, "both changed".
TEST(BenchTwin, AfterARebaselineTheReplayComparesWithTheBaselinesNightsValve) {
  constexpr int kNights = 6;
  const std::string dir = TwinLabDir("rebaseline");
  testing::ServerProcess server(dir, kLabNights, ResistanceStepBench(0.15, 2));
  server.AddArg("--simulate-nights");
  server.AddArg(std::to_string(kNights));
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();

  nlohmann::json first = WaitForNights(addr, 3, 200);
  ASSERT_GE(first.size(), 3u) << server.Log();
  std::reverse(first.begin(), first.end());
  const std::int64_t night3_batch = first[2]["batch_id"].get<std::int64_t>();
  // The code change first (nights_test's worse PI law, written beside and renamed into place: a night never
  // reads half a file), then the baseline that the nights read each night.
  ASSERT_EQ(testing::WriteWorseCiSuite(kSuites, dir + "/worse"), "");
  std::filesystem::rename(dir + "/worse/ci-current-hold.json", dir + "/ci-current-hold.json");
  ASSERT_EQ(SetBaselineFromBatch(addr, "rebased", night3_batch, dir + "/baseline.json"), "");

  nlohmann::json list = WaitForNights(addr, kNights, 280);
  ASSERT_EQ(list.size(), static_cast<std::size_t>(kNights)) << server.Log();
  std::reverse(list.begin(), list.end());
  EXPECT_EQ(list[1]["cause"], "valve") << list[1].dump(1) << server.Log();  // night 2 against the old baseline
  int judged = 0;
  for (int k = 3; k < kNights; ++k) {
    if (list[k]["baseline"].get<std::string>().rfind("rebased", 0) != 0) continue;  // read before the change
    ++judged;
    EXPECT_EQ(list[k]["verdict"], "regressed") << list[k].dump(1);
    EXPECT_EQ(list[k]["cause"], "code") << list[k].dump(1) << "\n" << server.Log();
    EXPECT_NE(list[k]["cause_reason"].get<std::string>().find("baseline's night"), std::string::npos)
        << list[k].dump(1);
  }
  EXPECT_GE(judged, 2) << list.dump(1);  // nights 5 and 6 at least read the new baseline
}

// The build recorded with each run settles "code or valve" where the spec is the baseline's: the lab sets its
// baseline from night 1's suite batch on this server (so its runs, and the build that ran them, are known), and
// the bench's coil is 15 % more resistive from night 3. Every regressed case judged against that baseline ran the
// baseline's spec on the same executable: `valve`, because no code changed, said in each case's reason with both
// builds in its record. Without the builds the same nights are decided by the replay alone.
TEST(BenchTwin, TheBaselinesSpecAndBuildMakeARegressionTheBenchs) {
  constexpr int kNights = 5;
  const std::string dir = TwinLabDir("build");
  testing::ServerProcess server(dir, kLabNights, ResistanceStepBench(0.15, 3));
  server.AddArg("--simulate-nights");
  server.AddArg(std::to_string(kNights));
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();

  nlohmann::json first = WaitForNights(addr, 1, 200);
  ASSERT_GE(first.size(), 1u) << server.Log();
  const std::int64_t night1_batch = first[first.size() - 1]["batch_id"].get<std::int64_t>();
  ASSERT_EQ(SetBaselineFromBatch(addr, "night1", night1_batch, dir + "/baseline.json"), "");
  nlohmann::json list = WaitForNights(addr, kNights, 300);
  ASSERT_EQ(list.size(), static_cast<std::size_t>(kNights)) << server.Log();

  auto store = db::OpenSqliteStore(server.db_path());
  ASSERT_TRUE(store.ok()) << store.status().message();
  auto night1 = runs::ListBatch(store->get(), night1_batch);
  ASSERT_TRUE(night1.ok() && !night1->empty());
  ASSERT_TRUE((*night1)[0].execution.has_value());
  const std::string build = (*night1)[0].execution->build;
  EXPECT_EQ(build.rfind("valvebench ", 0), 0u) << build;
  EXPECT_NE(build.find(" sha256:"), std::string::npos) << build;

  auto briefs = (*store)->ListRegressions(/*nights_only=*/true, 100);
  ASSERT_TRUE(briefs.ok()) << briefs.status().message();
  int judged = 0;
  for (const auto& b : *briefs) {
    auto rec = (*store)->GetRegression(b.id);
    ASSERT_TRUE(rec.ok()) << rec.status().message();
    const auto j = nlohmann::json::parse(rec->result_json);
    if (b.baseline_name != "night1" || !j.contains("cause")) continue;
    ++judged;
    EXPECT_EQ(j["cause"]["verdict"], "valve") << b.night << ": " << j["cause"].dump(1) << "\n" << server.Log();
    EXPECT_NE(j["cause"].value("reason", "").find("ran the spec and the build of the baseline's code (the baseline's "
                                                  "batch "),
              std::string::npos)
        << j["cause"].dump(1);
    for (const auto& c : j["cause"]["cases"]) {
      EXPECT_EQ(c.value("build", ""), build) << c.dump(1);
      EXPECT_EQ(c.value("baseline_build", ""), build) << c.dump(1);
      EXPECT_NE(c.value("reason", "").find("no code changed, the bench did"), std::string::npos) << c.dump(1);
    }
  }
  EXPECT_GE(judged, 2) << "nights 3 to 5 regress, and at least two read the baseline of night 1\n" << list.dump(1);
}

}  // namespace
}  // namespace vb
