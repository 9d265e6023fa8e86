// The bench twin on the server (issue 38, docs/track.md "On the server"): a bench's "health" block queues a
// switch-on check before each night's suite, an emulated bench's "drift" changes its valve night by night, and
// `benchctl health` tracks each bench's checks from the server's store. The config's blocks are validated with
// errors naming the field.
#include <gtest/gtest.h>

#include <chrono>
#include <nlohmann/json.hpp>
#include <set>
#include <thread>

#include "../common/run_command.h"
#include "runs/bench_setup.h"
#include "server/config.h"
#include "server/health_check.h"
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

  valvebench::v1::ExperimentSpec spec;
  EXPECT_EQ(runs::NightNumberOf(spec), 0);
  spec.add_tags("night");
  spec.add_tags(runs::NightNumberTag(17));
  EXPECT_EQ(runs::NightNumberOf(spec), 17);
}

// The health check's runs: one per supply and pressure, from rest with one gate step, pinned to the bench,
// tagged with the night, queued ahead of the suite.
TEST(HealthCheck, OneSwitchOnRunPerSupplyAndPressure) {
  auto c = testing::MinimalConfig();
  auto* h = c.mutable_benches(0)->mutable_health();
  h->add_supply_v(24.0), h->add_supply_v(20.0);
  h->add_supply_pressure_pa(1e5), h->add_supply_pressure_pa(4e5);
  auto s = server::SettingsFromConfig(c, "");
  ASSERT_TRUE(s.ok()) << s.status().message();
  const auto specs = server::HealthCheckSpecs(s->benches[0], "2026-11-29", 12);
  ASSERT_EQ(specs.size(), 4u);
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
  EXPECT_EQ(conditions.size(), 4u);
  // A bench without the block has no check.
  c.mutable_benches(0)->clear_health();
  auto none = server::SettingsFromConfig(c, "");
  ASSERT_TRUE(none.ok());
  EXPECT_TRUE(server::HealthCheckSpecs(none->benches[0], "2026-11-29", 1).empty());
}

// A lab of two emulated benches lives six nights in one start (--simulate-nights 6): emu-a's coil resistance is
// 4 % higher from night 4 (a corroding connector), emu-b does not change. `benchctl health` reads both benches'
// checks from the server, flags R on emu-a at or after night 4 (changing since night 4) and nothing on emu-b, and
// exits 1 (about 70 s: twelve identifications).
TEST(Health, ADriftingBenchIsFlaggedWithItsParameterAndTheCleanOneIsNot) {
  const std::string dir = ::testing::TempDir() + "/vb-health-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  const std::string health =
      R"("health": {"supply_V": [24, 20], "supply_pressure_Pa": [100000, 250000, 400000]}, "current_noise_A": 0.002)";
  const std::string benches =
      R"([{"name": "emu-a", "kind": "emulated", "model": {"preset": "taghizadeh2009"}, )" + health +
      R"(, "drift": [{"parameter": "R", "step": 0.04, "from_night": 4}]},
          {"name": "emu-b", "kind": "emulated", "model": {"preset": "taghizadeh2009"}, )" + health + "}]";
  const std::string nights = R"("nights": {"cron": "0 2 * * *", "suite_file": ")" + kSuites +
                             R"(ci.json", "baseline_file": ")" + kSuites + R"(ci-baseline.json", "timezone": "UTC"})";
  testing::ServerProcess server(dir, nights, benches);
  server.AddArg("--simulate-nights");
  server.AddArg("6");
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  const std::string nights_cmd =
      std::string(VB_BENCHCTL) + " nights --json --server " + addr + " --token " + testing::kViewerToken;
  nlohmann::json list;
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (std::chrono::steady_clock::now() < until) {
    const auto r = testing::RunCommand(nights_cmd);
    const size_t at = r.out.find('[');
    list = nlohmann::json::parse(at == std::string::npos ? std::string() : r.out.substr(at), nullptr, false);
    if (list.is_array() && list.size() >= 6) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
  }
  ASSERT_TRUE(list.is_array() && list.size() == 6) << list.dump(1) << "\n" << server.Log();
  std::vector<std::string> dates;
  for (const auto& n : list) dates.push_back(n["date"]);
  std::sort(dates.begin(), dates.end());

  const std::string health_cmd =
      std::string(VB_BENCHCTL) + " health --json --server " + addr + " --token " + testing::kViewerToken;
  const auto r = testing::RunCommand(health_cmd);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  const auto j = nlohmann::json::parse(r.out.substr(std::min(r.out.find('{'), r.out.size())), nullptr, false);
  ASSERT_TRUE(j.is_object()) << r.out;
  ASSERT_EQ(j["benches"].size(), 2u) << j.dump(1);
  for (const auto& b : j["benches"]) {
    EXPECT_EQ(b["nights"], 6) << b.dump(1);
    EXPECT_EQ(b["sessions"], dates) << b.dump(1);
  }
  ASSERT_FALSE(j["flags"].empty()) << j.dump(1);
  const auto& first = j["flags"][0];
  EXPECT_EQ(first["bench"], "emu-a") << j["flags"].dump(1);
  EXPECT_EQ(first["parameter"], "R") << j["flags"].dump(1);
  EXPECT_GE(first["session"].get<std::string>(), dates[3]) << j["flags"].dump(1);
  EXPECT_EQ(first["since"], dates[3]) << j["flags"].dump(1);
  EXPECT_NEAR(first["change_relative"].get<double>(), 0.04, 0.01) << first.dump(1);
  for (const auto& f : j["flags"]) {
    EXPECT_EQ(f["bench"], "emu-a") << "a flag on the clean bench: " << f.dump();
    EXPECT_GE(f["session"].get<std::string>(), dates[3]) << "a flag before the change: " << f.dump();
  }

  // A bench without checks: exit 2, named.
  const auto missing = testing::RunCommand(health_cmd + " emu-c");
  EXPECT_EQ(missing.exit_code, 2) << missing.out;
  EXPECT_NE(missing.out.find("no health checks stored for bench emu-c"), std::string::npos) << missing.out;
}

}  // namespace
}  // namespace vb
