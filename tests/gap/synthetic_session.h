// Synthetic bench sessions for the gap tests: the emulator with known effects on stands in for the bench (the
// catalog's effects are the emulator's), plus Gaussian sensor noise. Short runs keep the tests fast.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "gap/dataset.h"
#include "gap/replay.h"
#include "model/effects.h"
#include "model/params.h"

namespace vb::gap {

struct RunPlan {
  const char* id;
  double supply_V;
  double pwm_Hz;   // 0: one step on
  double duty;
  const char* split;
};

// Gate pattern: PWM at pwm_Hz and duty for 40 ms (or a 20 ms step), then 10 ms off.
inline std::vector<std::int8_t> Gate(const RunPlan& p, double dt) {
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

inline const std::vector<RunPlan>& Plans() {
  static const std::vector<RunPlan> plans = {
      {"step24", 24.0, 0, 1, "fit"},        {"pwm200_d60", 24.0, 200, 0.6, "fit"},
      {"pwm500_d40", 24.0, 500, 0.4, "fit"}, {"step18", 18.0, 0, 1, "holdout"},
      {"pwm300_d50_18", 18.0, 300, 0.5, "holdout"},
  };
  return plans;
}

inline Dataset Session(const model::PlantParams& truth, unsigned seed = 7, double noise_A = 2e-3) {
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
    r.split = *ParseSplit(p.split);
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

inline model::PlantParams With(const char* effect, std::vector<std::pair<std::string, double>> params) {
  model::PlantParams p = *model::Preset("taghizadeh2009");
  EXPECT_TRUE(model::AddEffect(&p.effects, effect, params).ok());
  return p;
}

}  // namespace vb::gap
