// Sliding-mode position control of a limited-travel solenoid (Lunge, Kurode, Chhibber, iNaCoMM 2013 = seed 002,
// section IV): a position SMC with Gao's power-rate reaching law makes the force demand, eq. 6 is inverted into
// a current demand, and a current SMC with a constant-rate reaching law (smoothed by a sigmoid) makes the coil
// voltage, realised by PWM at carrier_Hz. Both loops run once per carrier period. See docs/position-controllers.md.
#pragma once

#include <string_view>

#include "common/status.h"
#include "control/cascade_pi_position.h"  // LungeSolenoidModel, CoilVoltageCommand
#include "control/controller.h"

namespace vb::control {

// Position loop, every carrier period h = 1 / carrier_Hz, with e = x - x_d, edot = xdot - xdot_d:
//   s      = c1 e + edot                                                 (eq. 15/18, c^T = [c1 1])
//   u      = M (-c1 edot + xddot_d - k |s|^alpha sgn(s)) + K x + b xdot  (eq. 21 with eq. 20)
//   F_mag  = clamp(u + M g_r, 0, F_max(x))                               (eq. 22; a solenoid only pulls)
//   i_d    = sqrt(2 F_mag (a + x)^2 / (a L'))                           (eq. 23)
// xdot_d = Reference.rate; xddot_d = (rate - previous rate) / h when reference_accel_feedforward (0 on the first
// tick). F_max(x) is eq. 6 at current_limit_A.
// Current loop, s_i = i - i_d (eq. 24):
//   di_d/dt = (i_d - previous i_d) / h   (0 on the first tick)
//   v = L(x) (-k1 s_i / (|s_i| + delta) + di_d/dt) + R i* + i* xdot dL/dx   (eq. 29 with the sigmoid of IV.B)
//   i* = i_d when equivalent_control_at_demand (the equivalent control on the surface s_i = 0), else i
//   command = CoilVoltageCommand(clamp(v, v_min, supply_V), ...), v_min = -(supply_V + 2 V_d) with an H-bridge, else 0
// The paper prints the sigmoid as s/(s + delta); that is not odd in s and has a pole at s = -delta, so this law
// uses s/(|s| + delta), the usual smooth approximation of sgn(s).
//
// Needs position and velocity. When either is not finite the law refuses to run: gate 0, state cleared,
// state.mode = kModeNoPosition. Reference.command_on = false releases the coil (gate 0, mode = kModeReleased).
// A non-finite current or reference gives gate 0 for that tick with the state untouched (a transient fault).
// The finite differences use h = period_s(): an extra call (a Runner breakpoint) counts as a full period, which
// never divides by a tiny interval.
class SlidingModePosition final : public Controller {
 public:
  struct Params {
    double carrier_Hz = 20000.0;         // PWM carrier; the law runs once per carrier period
    double surface_slope_per_s = 200.0;  // c1 of c^T = [c1 1]: sliding-mode time constant 1/c1 = 5 ms. The
                                         // paper designs 5 (200 ms: after a step, 0.05 mm at 0.3 s is out of
                                         // reach); the steady error under a matched uncertainty scales as 1/c1
    double reaching_gain_SI = 3000.0;    // k of eq. 20, in (m/s)^(1 - alpha) / s; the paper's 1.5 is far too
                                         // weak in SI to reject the +-25 % model errors; at 5000 the loop
                                         // chatters through the current loop's lag (see docs)
    double reaching_exponent = 0.9;      // alpha of eq. 20, dimensionless, 0 < alpha < 1 (paper: 0.9)
    double current_reaching_rate_A_per_s = 500.0;  // k1 of eqs. 27-29, ~ the coil's top di/dt at 1 mm
                                                   // (230 V / 0.317 H = 725 A/s); the paper's 9 A/s also runs
                                                   // (R i_d carries the current) but corrects R errors less
    double current_boundary_layer_A = 0.05;        // delta of the sigmoid s/(|s| + delta); k1/delta = 1e4 1/s
                                                   // sets the per-tick current-loop gain to <= 0.5 (see docs)
    bool equivalent_control_at_demand = true;      // evaluate eq. 29's R i and i xdot dL/dx at i = i_d (on the
                                                   // surface) instead of the sampled i, which is the PWM ripple
                                                   // minimum and biases the law low; false = eq. 29 as printed
    bool reference_accel_feedforward = true;       // include xddot_d (finite difference of Reference.rate) in eq. 21
    double current_limit_A = 230.0 / 5540.0;       // i_d ceiling: the steady current at full supply (41.5 mA)
    bool h_bridge = false;                         // the bench's driver is an H-bridge (see CoilVoltageCommand)
    double bridge_diode_drop_V = 0.7;              // V_d of the H-bridge's body diodes (unused without h_bridge)
    LungeSolenoidModel model;                      // nominal plant values for eqs. 21-23 and 29
  };

  // state.x slots (units in brackets):
  static constexpr int kPrevCurrentDemand = 0;  // i_d of the previous tick [A], for di_d/dt
  static constexpr int kPrevReferenceRate = 1;  // Reference.rate of the previous tick [m/s], for xddot_d
  static constexpr int kForceUnclamped = 2;     // last u + M g_r before clamping [N] (telemetry)
  static constexpr int kPositionSurface = 3;    // last s of the position loop [m/s] (telemetry)
  static constexpr int kForceDemand = 4;        // last F_mag after clamping [N] (telemetry)
  static constexpr int kCurrentSurface = 5;     // last s_i = i - i_d [A] (telemetry)
  static constexpr int kVoltageDemand = 6;      // last v after clamping [V] (telemetry)
  static constexpr int kCurrentDemand = 7;      // last i_d [A] (telemetry)
  // state.mode values:
  static constexpr int kModeFirstTick = 0;  // no previous tick: finite differences are 0
  static constexpr int kModeRunning = 1;
  static constexpr int kModeReleased = 2;    // command_on was false on the last tick
  static constexpr int kModeNoPosition = 3;  // position or velocity missing: the law refused to run

  static Status Validate(const Params& p);
  static StatusOr<SlidingModePosition> Create(const Params& p);
  // The paper's design values (c1 = 5, k = 1.5, alpha = 0.9, k1 = 9) on the defaults of everything else.
  static Params PaperParams();
  // p must be valid (Validate); an invalid p is a programming error and aborts.
  explicit SlidingModePosition(const Params& p);

  std::string_view name() const override { return "sliding_mode_position"; }
  double period_s() const override { return 1.0 / p_.carrier_Hz; }
  SwitchCommand Step(const Measurement& m, const Reference& r, ControllerState* state) const override;
  int input_slot() const override { return kForceDemand; }  // seed 002's u: the force demand
  bool NeedsPosition() const { return true; }
  bool NeedsVelocity() const { return true; }
  const Params& params() const { return p_; }

  // The reaching-law terms, exposed for tests and docs.
  // Power-rate reaching rate k |s|^alpha sgn(s) (eq. 20, sign included) [m/s^2].
  double PowerRate(double s_mps) const;
  // Sigmoid s / (|s| + delta) [dimensionless, in (-1, 1)].
  double Sigmoid(double s_A) const;

 private:
  Params p_;
};

}  // namespace vb::control
