// Dither planner for low-frequency PWM: choose the PWM frequency and duty so that the parasitic current ripple
// (the "dither") has a requested amplitude at a requested current level.
//
// H. Kang, J. Park, J. Cho, J. Kim, J. Oh, "A new method for maintaining constant dither amplitude in low
// frequency PWM". Equation numbers below are the paper's; docs/dither.md has the derivations, our reproduction
// of the paper's Table I and the deviations we found.
//
// Model (paper Sec. II.B, Fig. 2): the coil is a series R-L; during the on-time D*T the switch puts supply_V on
// it, during the off-time (1-D)*T the current freewheels with 0 V across the coil (ideal diode, no fast-decay
// voltage). With tau = L/R and T = 1/f:
//
//     alpha = exp(-D T / tau)                                                        (6)
//     beta  = exp(-(1-D) T / tau)                                                    (7)
//     i_c   = (V/R) (1 - alpha) / (1 - alpha beta)      current at the end of the on-time (maximum)   (8)
//     i_d   = i_c * beta                                current at the end of the off-time (minimum)  (9)
//     I_avg = (i_c + i_d) / 2                                                        (10)
//     I_amp = i_c - i_d                                                              (11)
//
// Two conventions of the paper that are easy to misread:
//   * The paper's "average current" I_avg (eq. 10) is the MID-RANGE of the ripple, (max + min)/2, not the time
//     mean of the current. The exact time mean is a separate quantity, i_mean_A below; in steady state it equals
//     D * V/R exactly (the mean inductor voltage over a period is zero), for every frequency.
//   * The paper's "dither amplitude" I_amp (eq. 11) is PEAK-TO-PEAK (max - min), not the half-amplitude.
//
// Planner (paper Sec. IV.A): given (I_avg, I_amp), solve eqs. (10) and (11) for (f, D) inside the bounds of
// Fig. 7(a) -- "exact" -- or use the paper's simplified eqs. (12) I_avg = k1 D and (13) 1/I_amp = k2 f --
// "approximate", with slopes fitted once from the model (see FitApproxDitherModel).
//
// Pure functions, no global state, no exceptions. Errors are vb::Status InvalidArgument with a message naming
// the field. The success paths do not allocate except FitApproxDitherModel (its k2 table).
#pragma once

#include <optional>
#include <vector>

#include "common/status.h"

namespace vb::control {

// Series R-L coil driven by a low-side switch from a constant supply (paper Fig. 2).
struct RlCoil {
  double R_ohm = 28.5;     // coil resistance, > 0 (paper: HydraForce TS98-T34 at 20 degC)
  double L_H = 0.33;       // coil inductance, > 0 (paper: 330 mH)
  double supply_V = 24.0;  // voltage across the coil while the switch is on, > 0 (paper: 24 V)
};

// Periodic steady state of the coil current under PWM at (frequency_Hz, duty).
struct RlPwmSteadyStateResult {
  double i_max_A = 0.0;   // i_c, eq. (8): at the end of the on-time
  double i_min_A = 0.0;   // i_d, eq. (9): at the end of the off-time (= start of the on-time)
  double i_avg_A = 0.0;   // eq. (10): (i_max + i_min)/2, the paper's "average" (mid-range, NOT the time mean)
  double i_amp_A = 0.0;   // eq. (11): i_max - i_min, peak-to-peak ripple (the paper's "dither amplitude")
  double i_mean_A = 0.0;  // (1/T) * integral of i(t) over one period = duty * supply_V / R_ohm (exact)
};

// Eqs. (6)-(11). frequency_Hz > 0, duty in [0, 1]. Errors name "coil.R_ohm", "frequency_Hz", "duty", ...
StatusOr<RlPwmSteadyStateResult> RlPwmSteadyState(const RlCoil& coil, double frequency_Hz, double duty);

// What the user wants: the paper's two "desired values" (Table I).
struct DitherRequest {
  double average_current_A = 0.0;  // I_avg of eq. (10) (mid-range of the ripple), > 0
  double dither_amplitude_A = 0.0;        // I_amp of eq. (11) (peak-to-peak ripple), > 0
};

// Search box for (f, D): the paper's Fig. 7(a). Defaults are the paper's ("generally within 50 Hz to 1000 Hz";
// duty "commonly within 5 % to 95 % to avoid the dead zone").
struct DitherPlannerOptions {
  double min_frequency_Hz = 50.0;    // > 0; lowest PWM frequency the valve tolerates (spool follows the ripple)
  double max_frequency_Hz = 1000.0;  // > min_frequency_Hz
  double min_duty = 0.05;            // dimensionless, in [0, 1]
  double max_duty = 0.95;            // dimensionless, in (min_duty, 1]
};

// The answer: what to program into the PWM peripheral, and what the model (eqs. 10, 11) predicts it gives.
struct DitherPlan {
  double frequency_Hz = 0.0;  // PWM carrier frequency
  double duty = 0.0;          // dimensionless, 0..1
  double i_avg_A = 0.0;       // eq. (10) at (frequency_Hz, duty): mid-range of the ripple
  double i_amp_A = 0.0;       // eq. (11) at (frequency_Hz, duty): peak-to-peak ripple
  double i_mean_A = 0.0;      // exact time mean at (frequency_Hz, duty) = duty * V/R
};

// Exact method: solves eqs. (10) and (11) simultaneously for (f, D) inside the options' box.
//
// Method (all steps are bracketed TOMS 748 root solves, Boost.Math, so the result is as accurate as double allows):
//   1. For a frequency f, D_f(f) is the duty with I_avg(f, D) = average_current_A (I_avg is strictly increasing
//      in D at fixed f: a larger duty gives a pointwise larger periodic current).
//   2. D_f is monotone in f, so the frequencies with D_f(f) inside [min_duty, max_duty] form an interval
//      [f_lo, f_hi]; its ends are found by solving I_avg(f, duty bound) = average_current_A in f.
//   3. g(f) = I_amp(f, D_f(f)) is strictly decreasing in f; solve g(f) = dither_amplitude_A on [f_lo, f_hi].
// The monotonicity facts are checked numerically by the tests over a wide range of T/tau.
//
// Errors (InvalidArgument): a non-finite or non-positive request field; an average current that no duty in the
// box reaches ("dither.average_current_A: ... (reachable ...)"); an amplitude outside the controllable area of
// the paper's Fig. 7(b) at that average ("dither.dither_amplitude_A: 0.2 A is not reachable at average 0.1 A within f in
// [50, 1000] Hz and duty in [0.05, 0.95] (max 0.1234 A)"); a bad coil ("coil.R_ohm") or box ("options.min_duty").
StatusOr<DitherPlan> PlanDitherExact(const RlCoil& coil, const DitherRequest& request,
                                     const DitherPlannerOptions& options = {});

// The controllable dither range at one average current (a vertical cut through the paper's Fig. 7(b)).
struct DitherAmplitudeRange {
  double min_amplitude_A = 0.0;       // reached at the highest usable frequency (frequency_at_min_Hz)
  double max_amplitude_A = 0.0;       // reached at the lowest usable frequency (frequency_at_max_Hz)
  double frequency_at_min_Hz = 0.0;   // f_hi of PlanDitherExact step 2
  double frequency_at_max_Hz = 0.0;   // f_lo of PlanDitherExact step 2
  double duty_at_min = 0.0;           // D_f(f_hi)
  double duty_at_max = 0.0;           // D_f(f_lo)
};

// Feasibility query: the range of I_amp reachable at average_current_A with (f, D) inside the box. Any
// amplitude in [min_amplitude_A, max_amplitude_A] is plannable by PlanDitherExact. Errors as PlanDitherExact
// for the average current, coil and options.
StatusOr<DitherAmplitudeRange> DitherAmplitudeRangeAt(const RlCoil& coil, double average_current_A,
                                                      const DitherPlannerOptions& options = {});

// How the slopes of the approximate method are fitted from the model (the paper does not give them).
struct ApproxFitOptions {
  // k1 (eq. 12): least squares through the origin of I_avg(f, D) (eq. 10) against D over `k1_duty_points`
  // evenly spaced duties in [min_duty, max_duty], at this one frequency. Unset = options.max_frequency_Hz.
  // Any fit frequency >= ~600 Hz (and the f -> infinity limit k1 = V/R) reproduces the paper's Table I duty
  // column to its printed digits on the paper's coil; the band middle (525 Hz) gets one digit wrong.
  std::optional<double> k1_fit_frequency_Hz;
  int k1_duty_points = 91;  // >= 2; 91 = 1 % steps on the default 5..95 % box
  // k2 (eq. 13) depends on the duty (with one k2 every row of Table I would get the same frequency). For each of
  // `k2_duty_points` evenly spaced duties D_j in [min_duty, max_duty]: least squares through the origin of
  // 1/I_amp(f, D_j) (eq. 11) against f over `k2_frequency_points` evenly spaced frequencies in
  // [min_frequency_Hz, max_frequency_Hz] (the paper's Fig. 8(c) line, one per duty).
  int k2_duty_points = 91;        // >= 2; the table a stand-alone controller would store
  int k2_frequency_points = 96;   // >= 2; 96 = 10 Hz steps on the default 50..1000 Hz box
};

// The paper's approximate model, fitted in advance and cheap to evaluate (no exp(), as on a microcontroller).
struct ApproxDitherModel {
  RlCoil coil;                      // used only to report the model prediction (eqs. 10, 11) of a plan
  DitherPlannerOptions options;     // the box the slopes were fitted on; plans outside it are rejected
  double k1_A = 0.0;                // eq. (12): I_avg = k1_A * D                         [A per unit duty]
  double k1_fit_frequency_Hz = 0.0; // where k1 was fitted
  // eq. (13): 1/I_amp = k2(D) * f. Table of k2 at duty_grid[j] = min_duty + j*(max_duty-min_duty)/(n-1),
  // in 1/(A*Hz). Between grid duties the normalised slope 1/(k2 D (1-D)) (~ supply_V/L_H, nearly constant) is
  // interpolated linearly.
  std::vector<double> k2_per_A_Hz;
};

// Fits k1 and the k2(D) table for a coil and box (see ApproxFitOptions). Errors: bad coil, box or fit options.
StatusOr<ApproxDitherModel> FitApproxDitherModel(const RlCoil& coil, const DitherPlannerOptions& options = {},
                                                 const ApproxFitOptions& fit = {});

// k2(D) of the model, 1/(A*Hz): the table interpolated (see ApproxDitherModel), D clamped to the table's range.
double ApproxK2PerAHz(const ApproxDitherModel& model, double duty);

// Approximate method, eqs. (12)-(13): D = I_avg / k1, then f = 1 / (k2(D) * I_amp). The plan's i_avg_A and
// i_amp_A are eqs. (10)-(11) evaluated at the chosen (f, D), so they show the approximation's error. Errors
// (InvalidArgument) when D or f falls outside the model's box, naming the request field.
StatusOr<DitherPlan> PlanDitherApprox(const ApproxDitherModel& model, const DitherRequest& request);

}  // namespace vb::control
