// Odd but legal switch-on captures (issue 35, point 2): each ends in a finite identification or a clear refusal
// that says why, never a NaN, a crash or a hang. The captures are made with gap/switch_on_synth.h (our model
// through a scope chain with its artefacts); the identification runs on a small budget (the test checks that
// it ends well, not how well it fits: docs/real-data.md and perf/perf_identify.cc measure that).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <unistd.h>

#include "gap/dataset.h"
#include "gap/diagnose.h"
#include "gap/moving_valve.h"
#include "gap/scope_csv.h"
#include "gap/switch_on_synth.h"
#include "model/params.h"

namespace vb::gap {
namespace {

namespace fs = std::filesystem;

model::PlantParams Family() { return *model::Preset("taghizadeh2009"); }

// practice3's kind of valve (12 V, about 37 ohm) with eddy currents: it pulls in at 1-4 bar within 10 ms.
model::PlantParams Valve() {
  model::PlantParams p = Family();
  p.R_ohm = 37.0;
  p.effects.eddy_R_p_ohm = 900.0;
  return p;
}

struct Odd {
  const char* name;
  std::function<void(ScopeChain*, std::vector<SwitchOnRunPlan>*, model::PlantParams*)> make;
};

std::vector<SwitchOnRunPlan> Runs() {
  return {{"on_1bar", 12.0, 1e5, -1.0, "fit"}, {"on_2bar", 12.0, 2e5, -1.0, "fit"},
          {"on_4bar", 12.0, 4e5, -1.0, "fit"}, {"on_6bar", 12.0, 6e5, -1.0, "holdout"}};
}

const Odd kOdd[] = {
    {"offset_and_positive_spike", [](ScopeChain* s, auto*, auto*) { s->offset_A = 0.004; s->spike_A = 0.08; s->spike_samples = 2; }},
    {"offset_and_negative_spike", [](ScopeChain* s, auto*, auto*) { s->offset_A = -0.003; s->spike_A = -0.02; s->spike_samples = 3; }},
    {"clipped", [](ScopeChain* s, auto*, auto*) { s->clip_A = 0.2; }},
    {"eight_bit", [](ScopeChain* s, auto*, auto*) { s->lsb_A = 0.4 / 256.0; }},
    {"heavy_noise", [](ScopeChain* s, auto*, auto*) { s->noise_A = 0.05; s->averaged = 1; }},
    {"mains_ripple", [](ScopeChain* s, auto*, auto*) { s->ripple_A = 0.01; }},
    {"glitches", [](ScopeChain* s, auto*, auto*) { s->glitch_A = 0.1; s->glitches = 6; }},
    {"ten_kHz", [](ScopeChain* s, auto*, auto*) { s->sample_period_s = 1e-4; s->pre_trigger_s = 1e-3; }},
    {"inverted", [](ScopeChain* s, auto*, auto*) { s->inverted = true; }},
    {"open_coil", [](ScopeChain* s, auto*, auto*) { s->open_coil = true; }},
    {"one_run", [](ScopeChain*, auto* r, auto*) { r->resize(1); r->front().split = ""; }},
    {"never_pulls_in", [](ScopeChain*, auto* r, auto*) { for (auto& x : *r) x.supply_V = 4.0; }},
    {"one_pressure", [](ScopeChain*, auto* r, auto*) { for (auto& x : *r) x.supply_pressure_Pa = 3e5; }},
    {"no_eddy_stiff_spring", [](ScopeChain*, auto*, model::PlantParams* p) { p->effects.eddy_R_p_ohm = 0.0; p->k_N_per_m *= 3.0; }},
};

class OddCapture : public ::testing::TestWithParam<int> {};

TEST_P(OddCapture, EndsInAFiniteFitOrAClearRefusal) {
  const Odd& odd = kOdd[GetParam()];
  const fs::path dir = fs::temp_directory_path() / ("vb_odd_" + std::to_string(::getpid()) + "_" + odd.name);
  fs::remove_all(dir);
  ScopeChain scope;
  scope.noise_A = 2e-3;
  scope.averaged = 4;
  scope.duration_s = 0.006;  // short traces: a fast test
  scope.seed = 7 + static_cast<unsigned>(GetParam());
  auto runs = Runs();
  model::PlantParams truth = Valve();
  odd.make(&scope, &runs, &truth);
  ASSERT_TRUE(WriteSwitchOnSession(dir.string(), truth, runs, scope, odd.name).ok());
  auto ds = LoadDataset(dir.string(), model::PresetNames());
  if (!ds.ok()) {
    // The loader may refuse a capture (a trace not at rest before the edge): then with a message that says why.
    EXPECT_FALSE(ds.status().message().empty());
    fs::remove_all(dir);
    return;
  }
  MovingIdentifyOptions o;
  o.max_evaluations = 1500;
  o.threads = 1;
  auto id = IdentifyMovingValve(*ds, Family(), o);
  if (!id.ok()) {
    const std::string why = id.status().message();
    EXPECT_FALSE(why.empty());
    EXPECT_EQ(why.find("nan"), std::string::npos) << why;
    if (std::string(odd.name) == "open_coil") {
      EXPECT_NE(why.find("open coil"), std::string::npos) << why;
    }
  } else {
    EXPECT_NE(std::string(odd.name), "open_coil") << "an open coil has nothing to identify";
    // The budget holds (a hang or a runaway search is a failure), counted, not timed: the same on any machine.
    EXPECT_LE(id->evaluations, o.max_evaluations + 100) << odd.name;
    EXPECT_TRUE(std::isfinite(id->fit_rmse_A)) << odd.name;
    for (const auto& [name, v] : id->values) EXPECT_TRUE(std::isfinite(v)) << odd.name << ": " << name;
    for (const auto& [name, v] : id->fitted) EXPECT_TRUE(std::isfinite(v)) << odd.name << ": " << name;
    EXPECT_GT(id->plant.R_ohm, 0.0);
    EXPECT_GT(id->plant.N_turns, 0.0);
    for (const auto& r : id->landmarks) EXPECT_TRUE(std::isfinite(r.rmse_A)) << odd.name << " " << r.run;
    // The report and the JSON carry no NaN spelled out.
    const std::string json = MovingIdentificationJson(*id);
    EXPECT_EQ(json.find("nan"), std::string::npos) << json;
  }
  fs::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(Artefacts, OddCapture, ::testing::Range(0, static_cast<int>(std::size(kOdd))),
                         [](const auto& info) { return std::string(kOdd[info.param].name); });

// The cleaning itself: an offset from the pre-trigger samples and a spike at the edge, of either sign, are found
// and removed; a monotone rise with a jump at the edge (an eddy branch) is left alone.
TEST(CleanSwitchOnCapture, RemovesOffsetAndEdgeSpikeOfEitherSignAndKeepsAnEddyJump) {
  for (double sign : {1.0, -1.0}) {
    std::vector<double> i;
    std::vector<std::int8_t> gate;
    const double dt = 1e-5;
    for (int k = 0; k < 400; ++k) {
      const bool on = k >= 20;
      gate.push_back(on ? 1 : 0);
      const double t = (k - 20) * dt;
      double x = on ? 0.01 + 0.3 * (1.0 - std::exp(-t / 1e-3)) : 0.0;  // a jump, then the rise
      x += 0.005;                                                       // the offset
      if (k == 20) x += sign * 0.05;
      if (k == 21) x += sign * 0.025;
      x += 1e-4 * ((k * 7919) % 13 - 6) / 6.0;                          // a little deterministic noise
      i.push_back(x);
    }
    auto clean = i;
    const CaptureCleaning c = CleanSwitchOnCapture(&clean, gate, dt, 1e-4);
    EXPECT_NEAR(c.offset_A, 0.005, 2e-4) << sign;
    EXPECT_GE(c.spike_samples, 1) << sign;
    EXPECT_EQ(c.spike_A > 0, sign > 0);
    EXPECT_FALSE(c.inverted);
    EXPECT_NE(c.note.find("spike"), std::string::npos);
    // Past the spike the trace is the rise less the offset.
    for (int k = 30; k < 400; ++k) EXPECT_DOUBLE_EQ(clean[k], i[k] - c.offset_A);
    // Masked samples lie on the rise (within its local step), not at the spike.
    EXPECT_LT(std::abs(clean[20] - 0.01), 0.015) << sign;
  }
  // A clean monotone trace with an eddy jump: nothing is done.
  std::vector<double> i;
  std::vector<std::int8_t> gate;
  for (int k = 0; k < 300; ++k) {
    gate.push_back(k >= 10 ? 1 : 0);
    i.push_back(k >= 10 ? 0.02 + 0.2 * (1.0 - std::exp(-(k - 10) * 1e-5 / 5e-4)) : 0.0);
  }
  auto same = i;
  const CaptureCleaning c = CleanSwitchOnCapture(&same, gate, 1e-5, 1e-4);
  EXPECT_EQ(c.spike_samples, 0);
  EXPECT_EQ(c.offset_A, 0.0);
  EXPECT_EQ(same, i);
  // An inverted trace is negated.
  for (double& x : same) x = -x;
  const CaptureCleaning inv = CleanSwitchOnCapture(&same, gate, 1e-5, 1e-4);
  EXPECT_TRUE(inv.inverted);
  EXPECT_EQ(same, i);
}

}  // namespace
}  // namespace vb::gap
