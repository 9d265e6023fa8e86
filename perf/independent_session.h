// A switch-on session of the independent plant (perf/independent_valve.h) as the identification reads one: runs
// at the given supplies and pressures, each captured through the valve's scope, the gate rising at 0.1 ms of a
// 10.1 ms window, runs 2 s apart. Used by perf_identify (predict cases) and perf_changes (a reference and a target).
#pragma once

#include <cmath>
#include <cstddef>
#include <random>
#include <string>
#include <vector>

#include "gap/dataset.h"
#include "perf/independent_valve.h"

namespace vb::perf {

struct SessionRun {
  double supply_V;          // declared (the valve's supply_gain scales what it gets)
  double bar;               // the pressure the valve sees
  bool holdout = false;
  double declared_bar = -1.0;  // what the session declares (< 0: the true one)
};

inline gap::Dataset IndependentSession(const IndependentValve& v, const std::vector<SessionRun>& runs,
                                       std::mt19937& rng, const std::string& device, bool split) {
  const std::size_t on = static_cast<std::size_t>(std::llround(1e-4 / v.dt_s));
  const std::size_t n = on + static_cast<std::size_t>(std::llround(0.01 / v.dt_s)) + 1;
  // The switching spike comes with the switch's edge: the driver's delay moves it.
  const std::size_t edge = on + static_cast<std::size_t>(std::llround(v.delay_s / v.dt_s));
  gap::Dataset ds;
  ds.format = gap::kFormatValveRuns2;
  ds.model = "taghizadeh2009";
  ds.device = device;
  ds.sensor.noise_A = v.noise_A;
  ds.sensor.averaged = v.averaged;
  ds.sensor.adc_lsb_A = v.lsb_A;
  int r = 0;
  for (const SessionRun& p : runs) {
    gap::RunData run;
    const double declared = p.declared_bar >= 0.0 ? p.declared_bar : p.bar;
    run.id = "on" + std::to_string(r) + "_" + std::to_string(static_cast<int>(std::lround(declared * 10))) + "dbar";
    run.supply_V = p.supply_V;
    run.supply_pressure_Pa = declared * 1e5;
    run.t_start_s = 2.0 * r++;
    if (split) run.split = p.holdout ? vb::Split::kHoldout : vb::Split::kFit;
    run.sample_period_s = v.dt_s;
    const auto truth = SimulateSwitchOn(v, p.supply_V, p.bar * 1e5, n, on);
    run.i_A = Capture(v, truth, edge, rng);
    for (std::size_t k = 0; k < n; ++k) {
      run.t_s.push_back(static_cast<double>(k) * v.dt_s);
      run.gate.push_back(k >= on ? 1 : 0);
    }
    ds.runs.push_back(std::move(run));
  }
  return ds;
}

}  // namespace vb::perf
