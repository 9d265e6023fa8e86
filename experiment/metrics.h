// Run metrics, defined with formulas and units in docs/metrics.md. Computed from the recorded trace over a
// window [start_s, end_s], with the sample-and-hold convention: a sample's value holds until the next sample
// (exactly how the gate command behaves), so integrals are sums of value * sample_period -- unless the bench
// supplies exact running integrals (the emulator does), which are then used for effort, energy and switches.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "experiment/trace.h"

namespace vb::experiment {

enum class ControlledVariable { kNone, kCurrent, kPosition };

struct Metrics {
  // Tracking (NaN when the run has no reference): e = y - ref, y = i_A or x_m.
  double rmse = 0;              // sqrt(mean e^2)                        [A or m]
  double iae = 0;               // integral |e| dt                       [A s or m s]
  double max_abs_error = 0;     // max |e|                               [A or m]
  double overshoot = 0;         // max(0, max(y) - r_end) / |r_end - y_0| over the window  [1]
  double settling_time_s = 0;   // last instant |e| > 2 % of |r_end| (+ band floor), from window start [s]
  // Effort and wear
  double effort_l2 = 0;         // sqrt(integral v_coil^2 dt): Lunge's ||u||_2   [V s^0.5]
  double effort_rms = 0;        // sqrt(mean v_coil^2)                   [V]
  double energy_J = 0;          // integral v_coil i dt                  [J]
  double switches = 0;          // gate transitions                      [count]
  double mean_current_A = 0;    // mean i                                [A]
  // Valve (NaN without a position channel)
  double opening_delay_s = 0;   // first rising gate edge -> x reaches x_max
  double closing_delay_s = 0;   // first falling edge after opening -> x back at x_min
  double mean_position_m = 0;   // mean x (the static map of seed 000 Figs. 8-9)
  double mean_position_pct = 0; // 100 mean x / x_max
  double mean_flow_kg_per_s = 0;// mean of eq. (12) on the moving-average position
};

// x_min_m/x_max_m: the stops, for the valve delays (ignored without a position channel).
Metrics ComputeMetrics(const Trace& trace, ControlledVariable cv, double start_s, double end_s, double x_min_m,
                       double x_max_m);

// Metrics as (name, value) pairs in a fixed order, for tables, JSON and the database.
std::vector<std::pair<std::string, double>> MetricList(const Metrics& m);

}  // namespace vb::experiment
