// Mamdani fuzzy coil-current controller (PD-type rule base + resistive feedforward), PWM output.
//
// Najjari, Fotuhi, Vaezipour (2021), section 3.4, Table 1 (rules), eq. (21) (error definition), Fig. 6
// (feedforward structure and gain C_g). The paper does not print its membership functions (Fig. 8 only); the
// universes and scalings below are ours (docs/current-controllers.md).
//
// Inputs (both normalised by gains, like the paper's C_g, and clamped to [-1, 1]):
//   error      e  = i - i_d                     (eq. (21): E = A - D, actual minus desired)
//              e_n = e / error_scale_A
//   error rate de/dt ~ (i[k] - i[k-1]) / T - di_d/dt     (derivative on the measurement, plus the reference
//              rate from Reference::rate, so a reference step gives no derivative kick), optionally low-pass
//              filtered (first order, rate_filter_tau_s); rate_n = (de/dt) / rate_scale_A_per_s
// Input sets: NL NM ZE PM PL, triangles centred at -1, -0.5, 0, 0.5, 1 with half-width 0.5 (adjacent sets cross
//   at 0.5; since inputs are clamped, NL and PL act as shoulders).
// Output sets: VS S M L VL, triangles centred at -1, 0, 1, 2, 3 output steps with half-width 1 (universe [-2, 4]).
// Inference: AND = min, rule consequent clipped (min implication), aggregation = max, defuzzification = centroid,
//   computed exactly (piecewise-linear integration with all kink points; no grid, no allocation).
// Output voltage: v = feedforward_R_ohm * i_d + output_scale_V * u, u = centroid; clamped to [0, supply] and turned
//   into a duty with VoltageToPwm(). The law runs once per carrier period.
//
// Sign convention: Table 1 gives the largest voltage (VL) for error NL and rate NL and the smallest (VS) for
// error/rate PL, i.e. the output falls as the error rises. That regulates only with the paper's own eq. (21),
// e = i - i_d: current below the reference (e < 0) -> more voltage; current falling (de/dt < 0) -> more voltage
// ("when the bobbin current moves down, the voltage increases"). With e = i_d - i the same table would be
// positive feedback. The table is kept exactly as printed (kRuleTable).
//
// Equilibrium: at e = 0, de/dt = 0 only rule (ZE, ZE) -> S fires, u = 0, v = R_ff i_d: S is the "hold voltage",
// which is why the paper's table puts S (not M) at the centre. Row ZE reads L M S S VS, so u(e, 0) is flat (= 0)
// for 0 <= e_n <= 0.5: if the feedforward over-estimates the needed voltage the current can rest anywhere in
// [0, +error_scale_A/2] above the reference; if it under-estimates, it settles just below i_d on the NM-ZE slope
// (error = -dV / (2 output_scale_V / error_scale_A)). The ~0.7 V freewheel-diode loss makes the second case the
// usual one with R_ff = R.
//
// Release: when Reference::command_on is false the law outputs Gate(0) and resets its state.
// A non-finite current measurement is treated as a fault: Gate(0), state unchanged.
//
// ControllerState slots:
//   x[0]  previous current sample i[k-1] [A] (valid when mode == 1)
//   x[1]  (filtered) error rate de/dt [A/s]
//   x[2]  last defuzzified output u [output steps]   (diagnostic only)
//   x[3]  last commanded (saturated) voltage v [V]   (diagnostic only)
//   mode  0 = no previous sample yet (first tick after reset uses de/dt = 0), 1 = x[0] holds i[k-1]
#pragma once

#include <array>
#include <cstdint>
#include <string_view>

#include "common/status.h"
#include "control/controller.h"

namespace vb::control {

struct FuzzyCurrentParams {
  // Error gain: e_n = (i - i_d) / error_scale_A, so the sets NM/PM sit at -/+25 mA and NL/PL saturate at 50 mA.
  // With output_scale_V this gives a small-signal slope of 2*10 V / 0.05 A = 400 V/A near the set point (the
  // PI's kp is 377 V/A): loop bandwidth ~400/L = 3.3e3 rad/s on a 0.12 H coil.
  double error_scale_A = 0.05;
  // Error-rate gain: rate_n = (de/dt) / rate_scale_A_per_s. 1000 A/s makes the full-voltage rise of
  // taghizadeh2009 (~150-200 A/s) read as ZE..PM, so the rate only brakes near the set point; the implied
  // derivative gain ~10 V / 500 A/s = 0.02 V s/A is well below L (a discrete derivative gain near L rings).
  double rate_scale_A_per_s = 1000.0;
  // Time constant of the first-order low-pass on the error rate [s]; 0 = raw difference quotient. One carrier
  // period (50 us) damps sample noise at little lag.
  double rate_filter_tau_s = 50e-6;
  // Output gain [V per output step]: distance between adjacent output set centres (VS=-1 ... VL=+3 steps around
  // the feedforward). 10 V: VS drives the demand to 0 V (fast decay), L/VL saturate at the 24 V supply.
  double output_scale_V = 10.0;
  // Feedforward resistance [ohm]: the S set (hold) is placed at R_ff * i_d; 0 disables the feedforward.
  double feedforward_R_ohm = 13.0;
  // PWM carrier frequency [Hz]; the law runs once per carrier period (period_s = 1/carrier_Hz).
  double carrier_Hz = 20e3;
};

class FuzzyCurrent final : public Controller {
 public:
  using Params = FuzzyCurrentParams;

  // Linguistic values. Inputs: NL NM ZE PM PL; output: VS S M L VL.
  enum InputSet : std::uint8_t { kNL = 0, kNM, kZE, kPM, kPL };
  enum OutputSet : std::uint8_t { kVS = 0, kS, kM, kL, kVL };

  // Najjari et al. 2021, Table 1, exactly as printed: kRuleTable[error_rate][error], rows and columns NL..PL.
  static constexpr std::array<std::array<OutputSet, 5>, 5> kRuleTable = {{
      /* rate NL */ {kVL, kL, kL, kM, kM},
      /* rate NM */ {kL, kL, kM, kS, kS},
      /* rate ZE */ {kL, kM, kS, kS, kVS},
      /* rate PM */ {kM, kM, kVS, kVS, kVS},
      /* rate PL */ {kS, kS, kVS, kVS, kVS},
  }};
  // Input set centres (normalised universe, half-width 0.5) and output set centres (output steps, half-width 1).
  static constexpr std::array<double, 5> kInputCentres = {-1.0, -0.5, 0.0, 0.5, 1.0};
  static constexpr std::array<double, 5> kOutputCentres = {-1.0, 0.0, 1.0, 2.0, 3.0};

  // Names the offending field, e.g. "fuzzy.error_scale_A: must be > 0, got 0".
  static Status Validate(const Params& p);
  static StatusOr<FuzzyCurrent> Create(const Params& p);

  // Membership degrees of a normalised input (clamped to [-1, 1]) in NL..PL.
  static std::array<double, 5> Fuzzify(double x_n);
  // Firing strength of each output set (min for AND, max over rules with the same consequent).
  static std::array<double, 5> Fire(double error_n, double rate_n);
  // Exact centroid [output steps] of max_j min(alpha[j], tri_j(y)); 0 (the S centre) if nothing fires.
  static double Centroid(const std::array<double, 5>& alpha);
  // The whole inference: normalised error and rate -> defuzzified output u [output steps].
  static double Infer(double error_n, double rate_n) { return Centroid(Fire(error_n, rate_n)); }

  // Precondition: Validate(p).ok() (use Create() to check).
  explicit FuzzyCurrent(const Params& p = Params()) : p_(p) {}

  std::string_view name() const override { return "fuzzy_current"; }
  double period_s() const override { return 1.0 / p_.carrier_Hz; }
  ControllerState InitialState() const override { return {}; }
  SwitchCommand Step(const Measurement& m, const Reference& r, ControllerState* state) const override;

  const Params& params() const { return p_; }

  // State slot indices (see header comment).
  static constexpr int kPrevCurrent = 0;
  static constexpr int kRate = 1;
  static constexpr int kLastOutput = 2;
  static constexpr int kLastVoltage = 3;

 private:
  Params p_;
};

}  // namespace vb::control
