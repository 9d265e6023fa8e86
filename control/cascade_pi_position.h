// Cascade PI position control of a limited-travel solenoid (Lunge, Kurode, Chhibber, iNaCoMM 2013 = seed 002,
// section III, Fig. 4): an outer PI on the plunger position makes a magnetic-force demand, eq. 6 is inverted
// to turn it into a current demand (eq. 23), and an inner PI on the current makes the coil voltage, which the
// bench realises by PWM at carrier_Hz. Both loops run once per carrier period. See docs/position-controllers.md.
//
// This header also holds LungeSolenoidModel, the nominal plant values and the model equations (eqs. 5, 6, 23)
// that the two model-based position laws (this one and SlidingModePosition) carry as their own data: a
// controller never touches the emulator's model, it only knows the nominal values it was designed for.
#pragma once

#include <cmath>
#include <string_view>

#include "common/status.h"
#include "control/controller.h"

namespace vb::control {

// Nominal limited-travel solenoid of seed 002 (eqs. 5-7, Table I, with the project's b = 1.25 N s/m decision:
// the paper's own design matrix A22 = -b/M = -357 gives b = 1.25; Table I's 4.25 is taken as a typo).
//   L(x)  = L' x / (x + a)                       (eq. 5)
//   dL/dx = L' a / (x + a)^2
//   F_mag = (i^2 / 2) a L' / (a + x)^2           (eq. 6)
//   M xddot = F_mag - K x - M g_r - b xdot       (eq. 7)
//   i_d   = sqrt(2 F (a + x)^2 / (a L'))         (eq. 23, the inverse of eq. 6 for i >= 0)
struct LungeSolenoidModel {
  double mass_kg = 0.0035;                   // plunger mass M
  double spring_N_per_m = 90.5;              // return spring K
  double damping_N_s_per_m = 1.25;           // viscous friction b (see the b decision above)
  double gravity_mps2 = 9.8;                 // g_r, acting against the magnetic pull (0 for a horizontal mount)
  double inductance_scale_H = 2.2206609902;  // L' = pi d mu0 a N^2 / g with d = 8 mm, g = 1.2 mm, a = 6 mm, N = 3750
  double overlap_length_m = 0.006;           // a: length of the iron strips the flux passes through
  double coil_resistance_ohm = 5540.0;       // R

  // The fields' names in messages are prefixed with `prefix` (e.g. "model.").
  Status Validate(std::string_view prefix) const;

  // Inductance L(x) (eq. 5); x is clamped at 0 (L(0) = 0).
  double InductanceH(double x_m) const {
    const double x = x_m > 0.0 ? x_m : 0.0;
    return inductance_scale_H * x / (x + overlap_length_m);
  }
  // dL/dx = L' a / (x + a)^2.
  double InductanceSlopeH_per_m(double x_m) const {
    const double x = x_m > 0.0 ? x_m : 0.0;
    const double ax = overlap_length_m + x;
    return inductance_scale_H * overlap_length_m / (ax * ax);
  }
  // Magnetic pull for current i at position x (eq. 6). Always >= 0: the solenoid only pulls.
  double ForceN(double current_A, double x_m) const {
    return 0.5 * current_A * current_A * InductanceSlopeH_per_m(x_m);
  }
  // The current that makes the pull force_N at x (eq. 23). force_N <= 0 gives 0.
  double CurrentForForceA(double force_N, double x_m) const {
    if (!(force_N > 0.0)) return 0.0;
    return std::sqrt(2.0 * force_N / InductanceSlopeH_per_m(x_m));
  }
};

// Turns a coil-voltage demand into the switch command, for the bench's driver (model/driver.h):
// - low-side switch + flyback diode (h_bridge = false): off = freewheel at ~0 V, so duty = clamp(v / V, 0, 1)
//   (VoltageToPwm); a negative demand gives duty 0.
// - H-bridge (h_bridge = true): off = all switches open, the current returns to the supply through the body
//   diodes at -(V + 2 V_d) while i > 0 (fast decay; the driver has no slow-decay state). While i > 0 the PWM is
//   therefore bipolar, v_avg = d V - (1 - d)(V + 2 V_d), and duty = clamp((v + V + 2 V_d) / (2 V + 2 V_d), 0, 1);
//   with no current the off state is 0 V and duty = clamp(v / V, 0, 1). Gate -1 is never used: duty 0 already
//   applies the most negative voltage, -(V + 2 V_d), and gate -1 (-V) would drive the current negative.
// V = supply_V, V_d = diode_drop_V.
SwitchCommand CoilVoltageCommand(double v_coil_V, double supply_V, double carrier_Hz, bool h_bridge,
                                 double diode_drop_V, double current_A);

// Outer loop (position -> force), every carrier period h = 1 / carrier_Hz, e = x_ref - x:
//   F_ff  = K x_ref + M g_r                   (eq. 7 / 11 at rest at x_ref; when force_feedforward)
//   I_F  += Ki_x h e                          (backward Euler; skipped when it would push F further into a limit)
//   F_d   = clamp(F_ff + Kp_x e + I_F, 0, F_max(x)),  F_max(x) = eq. 6 at current_limit_A
// Force -> current (eq. 23):  i_d = sqrt(2 F_d (a + x)^2 / (a L'))   (<= current_limit_A by construction)
// Inner loop (current -> voltage), e_i = i_d - i:
//   V_ff  = R i_d                             (when voltage_feedforward)
//   I_V  += Ki_i h e_i                        (same conditional integration against [v_min, supply_V])
//   v     = clamp(V_ff + Kp_i e_i + I_V, v_min, supply_V),  v_min = -(supply_V + 2 V_d) with an H-bridge, else 0
//   command = CoilVoltageCommand(v, ...)      (PWM at carrier_Hz)
// Anti-windup on both loops is conditional integration (clamping): the integrator keeps its value on a tick
// where the updated output would lie outside its limits and the error pushes it further out.
//
// Needs the plunger position (not the velocity). When Measurement.position_m is not finite the law refuses to
// run: it returns gate 0, clears its integrators and sets state.mode = kModeNoPosition (a Runner should check
// NeedsPosition() against the bench's channels before starting). Reference.command_on = false releases the coil
// (gate 0, integrators cleared, mode = kModeReleased). A non-finite current or reference gives gate 0 for that
// tick with the state untouched (a transient fault, as in the current laws).
// The law assumes it is called every period_s(); an extra call (a Runner breakpoint) counts as a full period.
//
// The paper's gains (Kp = 17, Ki = 153 position; Kp = 0.1, Ki = 4 current) do not work in SI on this plant:
// the current loop's 4 V/(A s) would take ~10^3 s to build the ~170 V the coil needs; see the docs for the
// derivation of the defaults below and the test that shows it.
class CascadePiPosition final : public Controller {
 public:
  struct Params {
    double carrier_Hz = 20000.0;              // PWM carrier; the law runs once per carrier period (h = 1/carrier)
    double position_kp_N_per_m = 300.0;       // Kp_x: with the nominal M, b, K the loop's poles are -13 and
                                              // -172 +- 278j rad/s (wn 327 rad/s, zeta 0.53; see docs)
    double position_ki_N_per_m_s = 5000.0;    // Ki_x: the slow pole at -13 rad/s removes model errors
    double current_kp_V_per_A = 2770.0;       // Kp_i = 0.5 R: per-tick loop gain Kp_i / R = 0.5 (stable with a
                                              // one-tick PWM latency, see docs)
    double current_ki_V_per_A_s = 1.1e7;      // Ki_i = 0.1 R / h: removes the R mismatch in ~10 ticks
    bool force_feedforward = true;            // add F_ff = K x_ref + M g_r (eq. 7 at rest) to the outer PI
    bool voltage_feedforward = true;          // add V_ff = R i_d to the inner PI
    double current_limit_A = 230.0 / 5540.0;  // i_d ceiling: the steady current at full supply (41.5 mA)
    bool h_bridge = false;                    // the bench's driver is an H-bridge (see CoilVoltageCommand)
    double bridge_diode_drop_V = 0.7;         // V_d of the H-bridge's body diodes (unused without h_bridge)
    LungeSolenoidModel model;                 // nominal plant values for the feedforward and eq. 23
  };

  // state.x slots (units in brackets):
  static constexpr int kForceIntegral = 0;    // I_F, outer integrator [N]
  static constexpr int kVoltageIntegral = 1;  // I_V, inner integrator [V]
  static constexpr int kForceDemand = 2;      // last F_d after clamping [N] (telemetry)
  static constexpr int kCurrentDemand = 3;    // last i_d [A] (telemetry)
  static constexpr int kVoltageDemand = 4;    // last v after clamping [V] (telemetry)
  // state.mode values:
  static constexpr int kModeRunning = 0;
  static constexpr int kModeReleased = 1;    // command_on was false on the last tick
  static constexpr int kModeNoPosition = 2;  // the last measurement had no position: the law refused to run

  static Status Validate(const Params& p);
  static StatusOr<CascadePiPosition> Create(const Params& p);
  // p must be valid (Validate); an invalid p is a programming error and aborts.
  explicit CascadePiPosition(const Params& p);

  std::string_view name() const override { return "cascade_pi_position"; }
  double period_s() const override { return 1.0 / p_.carrier_Hz; }
  SwitchCommand Step(const Measurement& m, const Reference& r, ControllerState* state) const override;
  int input_slot() const override { return kForceDemand; }  // seed 002's u: the force demand
  bool NeedsPosition() const { return true; }
  bool NeedsVelocity() const { return false; }
  const Params& params() const { return p_; }

 private:
  Params p_;
};

}  // namespace vb::control
