// Pointwise-optimal one-step predictive coil-current controller.
//
// Najjari, Fotuhi, Vaezipour (2021), section 3.3, eqs. (7)-(11): minimise J = 1/2 w_I (I(t+h) - I_d)^2 +
// 1/2 w_v V^2 with I(t+h) expanded in a Taylor series truncated at the relative degree (1). The paper applies
// it to a 2-DOF ring-current model; we re-derive the same law for our coil (Taghizadeh et al. 2009, eq. (7)):
//
//     di/dt = (v - R i)/L(x) - (dL/dx) xdot i / L(x)  =  a + b v,
//     a = -(R i + E)/L,   b = 1/L,   E = (dL/dx) xdot i   (motional back-EMF, V)
//     L(x) = K / (l_c + 2 mu_r (x_t - x)),  K = N^2 A_e mu_r mu0,  dL/dx = 2 mu_r L^2 / K
//
// Prediction (first-order Taylor, eqs. (8)-(9)): i(t+h) = i + h (a + b v).
// Target: i*(t+h) = i_d + h * di_d/dt (Reference::rate; the paper has a constant I_d, rate = 0).
// Cost (eq. (10)): J(v) = 1/2 w_I (e + h a + h b v)^2 + 1/2 w_v v^2,   e = i - i*(t+h).
// dJ/dv = w_I h b (e + h a + h b v) + w_v v = 0 gives (our eq. (11)):
//
//     v* = -w_I h b (e + h a) / (w_I h^2 b^2 + w_v)
//        = k * [ L (i*(t+h) - i) / h  +  R i  +  E ],      k = h^2 / (h^2 + (w_v / w_I) L^2)  in (0, 1].
//
// d2J/dv2 = w_I h^2 b^2 + w_v > 0, so v* is the unique minimiser. k is dimensionless; k = 1 (w_v = 0) makes the
// predicted current land exactly on the target after h. Note: the paper's printed eqs. (11) and (13) misplace
// powers of h (h^2 + w_v c_e^2 N_1^2 / (w_I h^2) mixes s^2 with a pure number, and with w_v = 0 eq. (11) gives
// V = -c_e N_1 (e + h g_1) / h^2, not a voltage). Minimising their eq. (10) gives our form (c_e N_1 -> L), which
// is also what their eqs. (12)/(14) need, with their K equal to our dimensionless k.
//
// Position: when Measurement::position_m is finite (and use_measured_position) L = L(x) from the reluctance law
// params below (x clamped to [0, total_gap_m]); otherwise L = L_H (nominal). The back-EMF E uses dL/dx at the
// measured x and the measured velocity only when both are finite; otherwise E = 0 (the integrating effect of a
// missing back-EMF shows as a small transient error during spool motion only).
//
// Saturation: v* is clamped to [0, supply_V]; the low-side switch cannot put a negative average voltage on the
// coil (the freewheel diode gives only about -0.7 V), so a negative demand becomes duty 0. The law has no
// integrator, so there is no windup. Output: VoltageToPwm(v, supply_V, carrier_Hz), once per carrier period.
//
// Residual error (no integrator): with w_v > 0 (k < 1) the effort weight leaves a steady error of about
// (1 - k) R h i / (k L); the defaults give 0.06 % (0.3 mA at 0.5 A, L = 0.12 H). A voltage the model misses
// (resistance error dR i, the ~0.7 V (1 - duty) freewheel-diode loss, ...) leaves about dV h / (k L): 1 mA per
// 0.5 V. A smaller h shrinks both but the carrier delay bounds it (see horizon_s).
//
// Release: when Reference::command_on is false the law outputs Gate(0) and resets its state.
// A non-finite current measurement is treated as a fault: Gate(0), state unchanged.
//
// ControllerState slots (all diagnostic only; the law itself is memoryless):
//   x[0]  last unsaturated optimal voltage v* [V]
//   x[1]  inductance used at the last tick L [H]
//   x[2]  back-EMF used at the last tick E [V]
//   mode  1 if the last output was saturated, else 0
#pragma once

#include <string_view>

#include "common/status.h"
#include "control/controller.h"

namespace vb::control {

struct PredictiveCurrentParams {
  // Prediction horizon h [s]. 5 carrier periods: the loop then behaves like a first-order lag of time constant
  // ~h/k (bandwidth ~640 Hz), which tolerates the 1.5-period sampling + shadow-register delay (phase margin
  // ~73 deg at L = 0.12 H). h close to one carrier period would be dead-beat and ring with that delay.
  double horizon_s = 250e-6;
  // Weight of the predicted current error w_I [1/A^2] (> 0).
  double w_I_per_A2 = 1.0;
  // Weight of the control effort w_v [1/V^2] (>= 0). With w_I = 1: k = h^2/(h^2 + 1e-7 L^2) = 0.977 at L = 0.12 H,
  // i.e. 1 V of effort costs like 0.3 mA of predicted error; keeps k close to 1 (small offset) while the
  // weight stays visible, as in the paper's eq. (7).
  double w_v_per_V2 = 1e-7;
  // Nominal coil resistance R [ohm] (taghizadeh2009 identified value).
  double R_ohm = 13.0;
  // Nominal inductance L [H] used when the position is not measured (taghizadeh2009: 0.089 H closed, 0.143 H
  // open; 0.12 H is in between).
  double L_H = 0.12;
  // Use L(x) and the back-EMF from the measured position/velocity when they are finite.
  bool use_measured_position = true;
  // Reluctance law (Taghizadeh et al. 2009 eq. (4), Table 2) used when the position is measured:
  double turns = 1250.0;                 // N, coil turns [-]
  double core_area_m2 = 0.8e-4;          // A_e, effective flux-path cross section [m^2]
  double core_length_m = 0.115;          // l_c, magnetic path length in the core [m]
  double mu_r = 120.0;                   // relative permeability of the core [-]
  double total_gap_m = 0.4e-3;           // x_t, total air gap (travelling + holding) [m]
  // PWM carrier frequency [Hz]; the law runs once per carrier period (period_s = 1/carrier_Hz).
  double carrier_Hz = 20e3;
};

class PredictiveCurrent final : public Controller {
 public:
  using Params = PredictiveCurrentParams;

  // Names the offending field, e.g. "predictive.horizon_s: must be > 0, got 0".
  static Status Validate(const Params& p);
  static StatusOr<PredictiveCurrent> Create(const Params& p);

  // Precondition: Validate(p).ok() (use Create() to check).
  explicit PredictiveCurrent(const Params& p = Params()) : p_(p) {}

  std::string_view name() const override { return "predictive_current"; }
  double period_s() const override { return 1.0 / p_.carrier_Hz; }
  ControllerState InitialState() const override { return {}; }
  SwitchCommand Step(const Measurement& m, const Reference& r, ControllerState* state) const override;

  // The quantities the law uses at one tick (pure; no state).
  struct Terms {
    double L_H;        // inductance used
    double back_emf_V; // E = (dL/dx) xdot i, 0 when x or xdot is not measured
    double k;          // h^2 / (h^2 + (w_v/w_I) L^2)
    double v_opt_V;    // unsaturated minimiser v* of J
  };
  Terms Compute(const Measurement& m, const Reference& r) const;

  // Reluctance law: L(x) and dL/dx for the params' geometry (x clamped to [0, total_gap_m]).
  double InductanceAt(double x_m) const;
  double InductanceSlopeAt(double x_m) const;

  const Params& params() const { return p_; }

 private:
  double K() const;  // N^2 A_e mu_r mu0 [H m]
  Params p_;
};

}  // namespace vb::control
