// Run metrics, defined with formulas and units in docs/metrics.md. Computed from the recorded trace over a
// window [start_s, end_s], with the sample-and-hold convention: a sample's value holds until the next sample
// (exactly how the gate command behaves), so integrals are sums of value * sample_period -- unless the bench
// supplies exact running integrals (the emulator does), which are then used for effort, energy and switches.
#pragma once

#include <cstdint>
#include <limits>
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
  // What a switching law trades against tracking (docs/metrics.md "Effort per experiment kind").
  double switching_rate_Hz = 0; // gate transitions / window length                   [1/s]
  double diode_loss_W = 0;      // flyback diode conduction: V_d * integral(i, off) / T  [W]
  double switching_loss_W = 0;  // hard switching: sum over edges 1/2 (V_s + V_d) |i| t_c / T  [W]
  double driver_loss_W = 0;     // diode_loss_W + switching_loss_W                   [W]
  double effort_u_l2 = 0;       // sqrt(integral F_d^2 dt): seed 002's ||u||_2 on the law's force demand [N s^0.5]
  // Open-loop PWM (seed 003 dither; NaN for closed-loop laws)
  double pwm_frequency_Hz = 0;  // carrier the law commands at the window start      [Hz]
  double pwm_duty = 0;          // duty the law commands at the window start          [1]
  double ripple_pp_A = 0;       // max i - min i over the window: seed 003's I_amp (eq. 11) [A]
  double ripple_mid_A = 0;      // (max i + min i) / 2: seed 003's "average" I_avg (eq. 10) [A]
};

// The bench's driver, for the loss estimates (docs/metrics.md). Without it (supply_V NaN) the losses are NaN.
struct DriverLossInputs {
  double supply_V = std::numeric_limits<double>::quiet_NaN();
  double diode_drop_V = std::numeric_limits<double>::quiet_NaN();
  bool low_side_flyback = false;  // the loss split below holds for this driver only
  // Current-commutation time t_c of the switch (rise + fall of the voltage-current overlap). The emulated
  // switch is ideal and DriverParams has no timing, so this is an assumption: 100 ns, a logic-level MOSFET
  // driven from a microcontroller pin through a gate resistor at these currents (docs/metrics.md).
  double switch_transition_s = 100e-9;
};

// The metrics of a trace that arrives in blocks (the Runner streams traces to the store: docs/store.md, "Traces
// while the run executes"), sample by sample, in constant memory: ComputeMetrics() below is this over one
// whole trace, so both give the same numbers. The one quantity that needs the window's end before its last
// sample is the settling band (2 % of the final reference): it is taken from `final_ref_hint`, the reference at
// the window's last planned sample; if the run ends elsewhere (cancelled, failed) and the reference there
// differs, the settling time is NaN (a step response cut short has no settling time).
class MetricsAccumulator {
 public:
  MetricsAccumulator(ControlledVariable cv, double start_s, double end_s, double x_min_m, double x_max_m,
                     const DriverLossInputs& driver, double final_ref_hint);
  // Samples [from, to) of `block`, in time order after every sample added before.
  void Add(const Trace& block, size_t from, size_t to);
  void Add(const Trace& block) { Add(block, 0, block.size()); }
  Metrics Finish() const;

 private:
  void AddSample(const Trace& b, size_t k);

  ControlledVariable cv_;
  double start_s_, end_s_, x_min_m_, x_max_m_;
  DriverLossInputs driver_;
  double hint_ref_, hint_band_;
  double dt_ = 0.0;
  // The window's first and last samples.
  size_t count_ = 0;
  double t_first_ = 0.0, t_last_ = 0.0;
  double v2int_first_ = 0.0, v2int_last_ = 0.0, eint_first_ = 0.0, eint_last_ = 0.0, sw_first_ = 0.0,
         sw_last_ = 0.0;
  bool has_exact_ = false;
  double y0_ = 0.0, ref_first_ = 0.0, ref_last_ = 0.0, x_first_ = 0.0;
  std::int8_t gate_prev_ = 0;
  // Sums over the window.
  double v2_ = 0.0, p_ = 0.0, isum_ = 0.0, switches_ = 0.0, i_lo_ = 0.0, i_hi_ = 0.0;
  double e2_ = 0.0, ea_ = 0.0, emax_ = 0.0, ymax_ = 0.0, settle_ = 0.0;
  bool exceed_pending_ = false;
  double xs_ = 0.0, fs_ = 0.0;
  // The valve's delays: a small state machine over the window (seek the rising edge, the open stop, the
  // falling edge, the closed stop).
  enum class Valve { kSeekRise, kSeekOpen, kSeekFall, kSeekClosed, kDone };
  Valve valve_ = Valve::kSeekRise;
  double t_rise_ = 0.0, t_fall_ = 0.0, opening_s_ = 0.0, closing_s_ = 0.0;
  bool opened_ = false, closed_ = false;
};

// The driver's losses (docs/metrics.md) from m's energy_J, mean_current_A and switching_rate_Hz over a window of
// window_s; NaN unless the driver is the low-side switch with flyback diode.
void FillDriverLosses(Metrics* m, const DriverLossInputs& driver, double window_s);

// x_min_m/x_max_m: the stops, for the valve delays (ignored without a position channel).
// The driver's losses need `driver`; effort_u_l2 and the PWM command are filled by the Runner (NaN here).
Metrics ComputeMetrics(const Trace& trace, ControlledVariable cv, double start_s, double end_s, double x_min_m,
                       double x_max_m, const DriverLossInputs& driver = {});

// Metrics as (name, value) pairs in a fixed order, for tables, JSON and the database.
std::vector<std::pair<std::string, double>> MetricList(const Metrics& m);

}  // namespace vb::experiment
