// Drives a Simulator with a plain PWM schedule (no bench, no controller) and records samples and events.
#pragma once

#include <cmath>
#include <string>
#include <vector>

#include "model/simulator.h"

namespace vb::testing {

struct Recording final : model::SimObserver {
  std::vector<model::PlantSample> samples;
  struct Ev {
    model::EventKind kind;
    double t_s, i_A, x_m;
  };
  std::vector<Ev> events;
  void OnSample(const model::PlantSample& s) override { samples.push_back(s); }
  void OnEvent(model::EventKind k, double t, double i, double x, double) override {
    if (k != model::EventKind::kDriverSwitch) events.push_back({k, t, i, x});
  }
};

// Gate high for the first duty of each period from t = 0; duty 1 = constant high.
inline void RunPwm(model::Simulator& sim, double frequency_Hz, double duty, double duration_s, Recording* rec) {
  const double T = 1.0 / frequency_Hz;
  for (long n = 0; static_cast<double>(n) * T < duration_s - 1e-12; ++n) {
    const double ts = static_cast<double>(n) * T, te = ts + duty * T;
    sim.AdvanceTo(ts, rec);
    if (duty > 0) sim.SetGate(1);
    if (duty < 1) {
      sim.AdvanceTo(std::min(te, duration_s), rec);
      if (te < duration_s) sim.SetGate(0);
    }
  }
  sim.AdvanceTo(duration_s, rec);
  sim.EmitPendingSample(rec);
}

}  // namespace vb::testing
