// PI coil-current controller with PWM output.
//
// Najjari, Fotuhi, Vaezipour (2021), section 3.2 (and Taghizadeh et al. 2009, section 4, which holds the
// 0.5 A holding current of the same valve with "a separate PWM generator and a PI controller"). The paper gives
// no equation or gains; the law and its tuning here are ours.
//
// Law (runs once per PWM carrier period T = 1/carrier_Hz, error e = i_ref - i):
//
//     v_unsat[k] = kp * e[k] + I[k] + R_ff * i_ref[k]          (coil-voltage demand, V)
//     v[k]       = clamp(v_unsat[k], 0, supply_V)              (low-side switch: 0 V <= average v <= supply)
//     I[k+1]     = I[k] + ki * T * e[k]    unless the output is saturated and e[k] pushes further into the
//                                          saturation (conditional integration, "clamping")
//     command    = VoltageToPwm(v[k], supply_V, carrier_Hz)
//
// Anti-windup: conditional integration. The saturation limits are hard and asymmetric ([0, supply]) and the
// supply is a measured, varying quantity; conditional integration needs no extra tuning parameter (back-
// calculation needs a tracking gain) and freezes the integrator exactly while the output is pinned, so after the
// long saturated rise of a current step the integrator still holds the value it had before the step.
//
// Default gains: pole placement on the RL coil G(s) = 1/(L s + R). With C(s) = kp + ki/s the closed-loop
// characteristic polynomial is L s^2 + (R + kp) s + ki. Placing the poles at -w1 and -w2:
//     kp = L (w1 + w2) - R,      ki = L w1 w2.
// We choose w1 = R/L (the PI zero ki/kp then cancels the coil pole, so the reference response is first order
// with no overshoot) and w2 = 2 pi 500 Hz (crossover well below the 20 kHz carrier: the 1.5-period delay of
// sampling + shadow-registered duty costs 13.5 deg, phase margin ~76 deg), giving kp = L w2, ki = R w2. With
// L = 0.12 H, R = 13 ohm: kp = 377 V/A, ki = 40.8e3 V/(A s). FromPoles() computes other choices.
//
// Feedforward R_ff * i_ref (default R_ff = 13 ohm) supplies the steady coil voltage directly, so the integrator
// only trims the resistance error and the diode loss, and the slow cancelled mode (L/R ~ 9 ms) is barely excited.
//
// Release: when Reference::command_on is false the law outputs Gate(0) and resets the integrator.
// A non-finite current measurement is treated as a fault: Gate(0), state unchanged.
//
// ControllerState slots:
//   x[0]  integrator I [V]
//   x[1]  last commanded (saturated) coil voltage v [V]   (diagnostic only)
//   x[2]  last unsaturated demand v_unsat [V]             (diagnostic only)
//   mode  1 if the last output was saturated (integrator frozen or not), else 0   (diagnostic only)
#pragma once

#include <string_view>

#include "common/status.h"
#include "control/controller.h"

namespace vb::control {

struct PiCurrentParams {
  // Proportional gain [V/A]: L * w2 with L = 0.12 H and w2 = 2 pi * 500 rad/s (see header).
  double kp_V_per_A = 0.12 * 2.0 * 3.14159265358979323846 * 500.0;
  // Integral gain [V/(A s)]: R * w2 with R = 13 ohm (zero at R/L cancels the coil pole).
  double ki_V_per_A_s = 13.0 * 2.0 * 3.14159265358979323846 * 500.0;
  // Resistance used for the feedforward voltage R_ff * i_ref [ohm]; 0 disables the feedforward.
  double feedforward_R_ohm = 13.0;
  // PWM carrier frequency [Hz]; the law runs once per carrier period (period_s = 1/carrier_Hz).
  double carrier_Hz = 20e3;
};

class PiCurrent final : public Controller {
 public:
  using Params = PiCurrentParams;

  // Names the offending field, e.g. "pi.kp_V_per_A: must be >= 0, got -1".
  static Status Validate(const Params& p);
  static StatusOr<PiCurrent> Create(const Params& p);

  // Gains placing the closed-loop poles of the PI + RL-coil loop at -pole1_rad_s and -pole2_rad_s:
  // kp = L (p1 + p2) - R, ki = L p1 p2. Other fields keep their defaults. Validate() the result (kp may be < 0
  // when the poles are slower than the coil itself).
  static Params FromPoles(double L_H, double R_ohm, double pole1_rad_s, double pole2_rad_s);

  // Precondition: Validate(p).ok() (use Create() to check).
  explicit PiCurrent(const Params& p = Params()) : p_(p) {}

  std::string_view name() const override { return "pi_current"; }
  double period_s() const override { return 1.0 / p_.carrier_Hz; }
  ControllerState InitialState() const override { return {}; }
  SwitchCommand Step(const Measurement& m, const Reference& r, ControllerState* state) const override;

  const Params& params() const { return p_; }

  // State slot indices (see header comment).
  static constexpr int kIntegrator = 0;
  static constexpr int kLastVoltage = 1;
  static constexpr int kLastDemand = 2;

 private:
  Params p_;
};

}  // namespace vb::control
