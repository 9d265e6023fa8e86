// Effects: named, parameterised additions to a nominal model (issue 5's catalog; the names are part of the
// diagnosis output contract). The emulator runs with them (an emulated bench with effects stands in for
// hardware) and the gap diagnosis fits them. Each parameter has a unit and physical bounds.
//
// Simulated:
//   supply_resistance  R_s [ohm]: the source impedance; while the switch connects the supply, the coil sees
//                      V - R_s i. The freewheel loop does not include it.
//   supply_voltage     the supply delivers gain x its declared voltage (a sagging, mis-set or mislabelled supply):
//                      every segment the supply drives has V = gain x supply_V. Unlike sensor_gain it changes
//                      the current itself, so the force (i^2) and the plunger's timing follow it.
//   driver_delay       the driver switches delay_s after its gate command (a slower gate drive, an opto-isolator,
//                      a switch's turn-on delay): the coil sees each gate edge delay_s late; the recorded gate is
//                      the command. On a switch-on it is a shift of the whole current, which a sense chain's
//                      latency (sensor_lag.delay_s) would make too.
//   coil_heating       R(T) = R (1 + alpha dT), one thermal node: C_th d(dT)/dt = i^2 R(T) - dT / R_th
//                      (copper alpha = 3.93e-3 1/K). dT0_K is the coil's temperature rise when the run starts.
//   eddy_currents      a loss resistance R_p across the magnetising inductance (one eddy branch): the flux and
//                      the force follow the magnetising current, which lags the terminal current; the measured
//                      (terminal) current jumps at switching edges by dv/R_p.
//   sensor_lag         the current sensor: a first-order lag tau_s and a latency delay_s, applied to the sampled
//                      terminal current (exact for a current linear between samples); controllers see the
//                      latest reading. Needs a sample rate (the chain works on samples).
//   magnetic_saturation  the core's flux saturates, the air path's does not: lambda = lambda_s tanh(Lc i /
//                      lambda_s) + La i with La = L/mu_r, Lc = L - La, lambda_s = N A_e B_sat (the linear law
//                      is its small-current limit). The coil law uses d lambda/di and d lambda/dx; the force
//                      is the exact co-energy derivative at constant i.
//   end_stop_bounce    an elastic impact at either stop: the spool rebounds with -e v (coefficient of restitution
//                      e); an impact slower than v_stick_mps ends at rest (no infinite bounce sequence).
//   coulomb_friction   dry friction (Karnopp): a moving spool feels -F_c sgn(v); a spool at rest stays until the
//                      net force exceeds the static F_s (>= F_c), mid-travel or at a stop.
//   residual_magnetism a rate-independent hysteresis of the core: the flux follows the flux-equivalent current
//                      j = alpha i + (1 - alpha) P_w(i), P_w a play operator of half-width w (the coercive
//                      current H_c l_c / N) and alpha its reversible fraction. De-energised, P_w stays at w: a
//                      remanent flux that delays the release (and, rising, the lift); inside the band the
//                      coil's incremental inductance is alpha L. im0 is the play's state when the run starts.
//   sensor_offset      the current-sense chain reads offset_A more than the current (an amplifier or ADC offset).
//   sensor_gain        the current-sense chain reads gain x the current (a shunt or amplifier gain off its
//                      nominal value). Offset and gain act on what the sensor reports, after sensor_lag.
//   resistance_temperature  the winding resistance at a known temperature: R(T) = R (1 + alpha (T - T_ref)),
//                      R being the resistance at T_ref. A static covariate, not a dynamic state: it applies
//                      to runs that carry a winding (or ambient) temperature (model::AtState), e.g. readings
//                      taken at several chamber temperatures; coil_heating is the dynamic self-heating.
// (asking for them is an error that says so).
#pragma once

#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "common/status.h"

namespace vb::model {

struct Effects {
  double supply_R_ohm = 0.0;          // supply_resistance.R_s
  double supply_gain = 1.0;           // supply_voltage.gain; 1 = the declared voltage
  double driver_delay_s = 0.0;        // driver_delay.delay_s; 0 = none
  bool heating = false;               // coil_heating
  double heating_alpha_per_K = 3.93e-3;
  double heating_R_th_K_per_W = 2.0;
  double heating_C_th_J_per_K = 0.6;
  double heating_dT0_K = 0.0;
  double eddy_R_p_ohm = 0.0;          // eddy_currents.R_p; 0 = none
  double sensor_tau_s = 0.0;          // sensor_lag.tau_s; 0 = none
  double sensor_delay_s = 0.0;        // sensor_lag.delay_s
  double saturation_B_T = 0.0;        // magnetic_saturation.B_sat; 0 = none
  double saturation_tanh = 0.0;       // magnetic_saturation.tanh: 0 = Frohlich's knee (default), 1 = tanh, 2 = arctan,
                                      // 3 = the core in series with the gap (model/coil.h)
  double bounce_e = 0.0;              // end_stop_bounce.e; 0 = inelastic (nominal)
  double bounce_v_stick_mps = 1e-3;   // end_stop_bounce.v_stick
  double friction_F_c_N = 0.0;        // coulomb_friction.F_c (kinetic)
  double friction_F_s_N = 0.0;        // coulomb_friction.F_s (static, >= F_c)
  double residual_w_A = 0.0;          // residual_magnetism.w (play half-width); 0 = none
  double residual_alpha = 0.35;       // residual_magnetism.alpha (reversible fraction)
  double residual_im0_A = 0.0;        // residual_magnetism.im0
  double sensor_offset_A = 0.0;       // sensor_offset.offset_A
  double sensor_gain = 1.0;           // sensor_gain.gain; 1 = none
  bool temperature = false;           // resistance_temperature
  double temperature_alpha_per_K = 3.93e-3;  // resistance_temperature.alpha (copper: 3.93e-3 1/K at 20 C)
  double temperature_ref_C = 20.0;    // resistance_temperature.T_ref: the temperature R is given at

  // Effects that need the general (integrated) path: the closed form assumes a constant R and L.
  // (The sensor chain works on samples and leaves the plant on its fast path.)
  bool NeedsGeneralPath() const {
    return heating || eddy_R_p_ohm > 0.0 || saturation_B_T > 0.0 || friction_F_s_N > 0.0 || friction_F_c_N > 0.0 ||
           residual_w_A > 0.0;
  }
  bool any() const {
    return supply_R_ohm > 0.0 || supply_gain != 1.0 || driver_delay_s > 0.0 || NeedsGeneralPath() ||
           sensor_delay_s > 0.0 || bounce_e > 0.0 || sensor_chain();
  }
  // The static part of the sense chain (offset, gain) is not the identity.
  bool sensor_chain() const { return sensor_offset_A != 0.0 || sensor_gain != 1.0; }
  bool friction() const { return friction_F_c_N > 0.0 || friction_F_s_N > 0.0; }
};

// The catalog: every effect name of the contract, whether the simulator implements it, and its parameters.
struct EffectParamInfo {
  std::string_view name;
  std::string_view unit;
  double Effects::*field;
  double min, max;
};
struct EffectInfo {
  std::string_view name;
  std::string_view meaning;
  bool simulated;
  std::vector<EffectParamInfo> params;
};
const std::vector<EffectInfo>& EffectCatalog();

// One effect parameter by its dotted name ("coulomb_friction.F_c"), as fits report them; InvalidArgument naming
// the name when the effect or parameter is unknown, or (set) the value is outside the parameter's bounds.
// Setting coulomb_friction.F_c above F_s raises F_s with it (static friction is at least the kinetic).
StatusOr<double> GetEffectParam(const Effects& e, std::string_view dotted);
Status SetEffectParam(Effects* e, std::string_view dotted, double value);
std::vector<std::string> EffectNames();  // including "none" and the param:NAME form

// Turns an effect on with the given parameters (unspecified ones keep their defaults). Errors name the effect
// and the parameter: unknown names, values outside the physical bounds, effects not simulated yet.
Status AddEffect(Effects* effects, std::string_view name, const std::vector<std::pair<std::string, double>>& params);

}  // namespace vb::model
